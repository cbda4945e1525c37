"""Batched sub-pixel image registration by upsampled-DFT cross-correlation."""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar._checks import check_int
from torchsar.errors import InputTypeError, InputValueError, OptionError, ShapeError

__all__ = ["estimate_shift"]


def _check_pair(ref: object, mov: object) -> None:
    """Both tensors, same shape, at least 2-D, floating or complex."""
    for name, x in (("ref", ref), ("mov", mov)):
        if not isinstance(x, Tensor):
            raise InputTypeError(f"{name} must be a torch.Tensor, got {type(x).__name__}")
        if not (x.is_floating_point() or x.is_complex()):
            raise InputTypeError(f"{name} must be floating or complex, got {x.dtype}")
        if x.dim() < 2:
            raise ShapeError(f"{name} must have shape (..., H, W), got {tuple(x.shape)}")
    if ref.shape != mov.shape:  # type: ignore[union-attr]
        raise ShapeError(
            f"ref and mov must have the same shape, got {tuple(ref.shape)} and {tuple(mov.shape)}"  # type: ignore[union-attr]
        )
    for name, x in (("ref", ref), ("mov", mov)):
        if not bool(torch.isfinite(x).all()):  # type: ignore[arg-type]
            raise InputValueError(f"{name} must be finite, got NaN or Inf values")


def _upsampled_dft(data: Tensor, region: int, up: int, offsets: Tensor) -> Tensor:
    """DFT of ``data (..., H, W)`` on a ``region x region`` patch of the ``up``-times finer grid.

    ``offsets (..., 2)`` place the patch (per batch element); equals zero-padding by ``up``,
    FFT and cropping, at matrix-multiply cost (Guizar-Sicairos et al. 2008, eq. 12).
    """
    h, w = data.shape[-2:]
    real = data.real.dtype
    k = torch.arange(region, dtype=real, device=data.device)

    def kernel(n: int, off: Tensor) -> Tensor:
        f = torch.fft.fftfreq(n, d=float(up), dtype=real, device=data.device)
        arg = (k - off[..., None])[..., :, None] * f  # (..., region, n)
        return torch.polar(torch.ones_like(arg), -2 * math.pi * arg)

    out = data @ kernel(w, offsets[..., 1]).transpose(-1, -2)  # (..., H, region)
    return kernel(h, offsets[..., 0]) @ out  # (..., region, region)


def _argmax2(x: Tensor) -> Tensor:
    """``(row, col)`` of the maximum of ``|x|`` over the last two dims, float ``(..., 2)``."""
    w = x.shape[-1]
    i = x.abs().flatten(-2).argmax(-1)
    return torch.stack([i // w, i % w], dim=-1)


def estimate_shift(
    ref: Tensor, mov: Tensor, *, upsample: int = 20, normalization: str | None = None
) -> Tensor:
    """Sub-pixel translation registering ``mov`` with ``ref``, batched over leading dims.

    Cross-correlation through the FFT locates the integer peak; the peak is then refined on
    a ``1/upsample`` pixel grid in a 1.5-pixel neighbourhood by an upsampled DFT (matrix
    products, no large zero-padded FFT). Same algorithm and sign convention as
    :func:`skimage.registration.phase_cross_correlation`: if ``mov`` is ``ref`` translated
    by ``+d`` pixels, the result is ``-d`` (the shift to apply to ``mov``).

    Args:
        ref: real or complex ``(..., H, W)``; for SAR chips pass amplitude or intensity.
        mov: same shape as ``ref``.
        upsample: refinement factor (precision ``1/upsample`` pixel); 1 = integer peak.
        normalization: ``None`` (plain cross-correlation, robust for smooth blobs and
            noise) or ``"phase"`` (phase correlation, Kuglin & Hines).

    Returns:
        ``(..., 2)`` shifts ``(row, col)`` in pixels, in the real dtype of the input
        (float64 for float64/complex128, else float32).

    Raises:
        InputTypeError, ShapeError, OptionError: bad input; InputValueError: NaN or Inf.

    Shape:
        ``(..., H, W), (..., H, W)`` -> ``(..., 2)``.

    References:
        M. Guizar-Sicairos, S. T. Thurman, J. R. Fienup, "Efficient subpixel image
        registration algorithms", Opt. Lett. 33(2), 2008, doi:10.1364/OL.33.000156.

    Examples:
        >>> y, x = torch.meshgrid(torch.arange(32.0), torch.arange(32.0), indexing="ij")
        >>> blob = lambda cy, cx: torch.exp(-((y - cy) ** 2 + (x - cx) ** 2) / 8)
        >>> estimate_shift(blob(16, 16), blob(17.25, 15.5)).tolist()
        [-1.25, 0.5]
    """
    _check_pair(ref, mov)
    up = check_int(upsample, "upsample", minimum=1)
    if normalization not in (None, "phase"):
        raise OptionError(f"normalization must be None or 'phase', got {normalization!r}")
    cdt = torch.complex128 if ref.dtype in (torch.float64, torch.complex128) else torch.complex64
    if ref.numel() == 0:
        return torch.zeros(*ref.shape[:-2], 2, dtype=cdt.to_real(), device=ref.device)
    prod = torch.fft.fft2(ref.to(cdt)) * torch.fft.fft2(mov.to(cdt)).conj()
    if normalization == "phase":
        eps = torch.finfo(prod.real.dtype).eps
        prod = prod / prod.abs().clamp(min=100 * eps)
    size = torch.tensor(prod.shape[-2:], device=prod.device)
    shift = _argmax2(torch.fft.ifft2(prod))
    shift = torch.where(shift > size // 2, shift - size, shift).to(prod.real.dtype)
    if up > 1:
        shift = torch.round(shift * up) / up
        region = math.ceil(1.5 * up)
        center = float(region // 2)
        cc = _upsampled_dft(prod.conj(), region, up, center - shift * up).conj()
        shift = shift + (_argmax2(cc).to(shift.dtype) - center) / up
    return torch.where(size > 1, shift, torch.zeros_like(shift))
