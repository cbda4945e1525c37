"""Phase gradient autofocus (PGA) for 1-D (per-pulse) phase errors (Wahl et al. 1994).

Image rows are cross-range (one row per pulse after the azimuth transform), columns range.
Each iteration: centre-shift the brightest scatterer of every range column, window it
around the centre with a width read from the range-summed intensity profile, transform the
windowed columns back to the pulse domain, estimate the phase gradient with the
phase-difference (maximum-likelihood) kernel summed over range, integrate, remove the linear
trend and correct. Iterates until the RMS phase update is below ``tol``.
"""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar._checks import check_image, check_int, check_positive
from torchsar._scale import unit_scale
from torchsar.errors import OptionError, ShapeError
from torchsar.imaging._dtypes import as_complex
from torchsar.imaging.result import AutofocusResult

__all__ = ["pga"]


def _azimuth_fft(x: Tensor) -> Tensor:
    """Centred orthonormal FFT along rows (image -> pulse domain), dim -2."""
    return torch.fft.fftshift(torch.fft.fft(torch.fft.ifftshift(x, -2), dim=-2, norm="ortho"), -2)


def _azimuth_ifft(x: Tensor) -> Tensor:
    return torch.fft.fftshift(torch.fft.ifft(torch.fft.ifftshift(x, -2), dim=-2, norm="ortho"), -2)


def _centre_shift(img: Tensor) -> Tensor:
    """Circularly shift each column so its brightest sample sits at row ``H // 2``."""
    h = img.shape[-2]
    peak = img.abs().argmax(dim=-2, keepdim=True)  # (B, 1, W)
    rows = (torch.arange(h, device=img.device)[:, None] + peak - h // 2) % h  # (B, H, W)
    return torch.gather(img, -2, rows)


def _window(shifted: Tensor, level_db: float, min_width: int) -> Tensor:
    """Rectangular window around the centre, width from the range-summed intensity profile."""
    h = shifted.shape[-2]
    profile = shifted.abs().square().sum(dim=-1)  # (B, H)
    above = profile >= profile.amax(dim=-1, keepdim=True) * 10 ** (level_db / 10)
    dist = (torch.arange(h, device=shifted.device) - h // 2).abs()
    half = torch.where(above, dist, torch.zeros_like(dist)).amax(dim=-1)  # (B,)
    half = half.clamp_min(min_width // 2)
    keep = dist[None] <= half[:, None]  # (B, H)
    return shifted * keep[:, :, None]


def _gradient_phase(data: Tensor) -> Tensor:
    """Phase-difference estimate, integrated and de-trended, ``(B, H)``."""
    diff = (data[:, 1:] * data[:, :-1].conj()).sum(dim=-1).angle()  # (B, H-1)
    phi = torch.cat([torch.zeros_like(diff[:, :1]), diff.cumsum(dim=-1)], dim=-1)
    t = torch.arange(phi.shape[-1], dtype=phi.dtype, device=phi.device)
    tc = t - t.mean()
    slope = (phi * tc).sum(-1, keepdim=True) / tc.square().sum().clamp_min(1)
    phi = phi - slope * tc
    return phi - phi.mean(-1, keepdim=True)


def pga(
    image: Tensor,
    *,
    max_iter: int = 20,
    tol: float = 1e-3,
    window_db: float = -20.0,
    min_window: int = 3,
) -> AutofocusResult:
    """Phase gradient autofocus of complex images with per-pulse (row) phase errors.

    PGA does not depend on the image's scale; each item is processed scaled to unit peak
    amplitude (by a power of two, exactly), so images of any magnitude are focused without
    overflow.

    Args:
        image: complex image ``(B, 1, H, W)`` formed by :func:`ifft2c` (rows = pulses);
            complex128 is computed in double precision, every other complex dtype in
            complex64.
        max_iter: iteration limit.
        tol: stop an item when the RMS phase update (radians) falls below this.
        window_db: the window spans the rows whose range-summed intensity is within this
            many dB of the peak (re-measured every iteration, so it shrinks as focus improves).
        min_window: smallest window width in rows.

    Returns:
        :class:`AutofocusResult`: corrected ``image`` ``(B, 1, H, W)``, ``phase`` ``(B, H)``
        (the per-pulse error estimate, convention ``g = exp(1j phase) C f``), ``iterations``.

    Raises:
        InputTypeError, ShapeError: ``image`` is not a complex ``(B, 1, H, W)`` tensor.
        OptionError: invalid option.

    References:
        Wahl, Eichel, Ghiglia & Jakowatz, "Phase gradient autofocus - a robust tool for high
        resolution SAR phase correction", IEEE Trans. AES 30(3), 1994, doi:10.1109/7.303752.

    Examples:
        >>> from torchsar.imaging import fft2c, ifft2c, apply_phase_error
        >>> f = torch.zeros(1, 1, 32, 32, dtype=torch.complex64); f[0, 0, 8, 20] = 1
        >>> phi = 3 * torch.linspace(-1, 1, 32)[None] ** 2
        >>> blurred = ifft2c(apply_phase_error(fft2c(f[:, 0]), phi)).unsqueeze(1)
        >>> out = pga(blurred)
        >>> float(out.image.abs().max()) > 0.99
        True
    """
    image = check_image(image, "image", complex_ok=True, real_ok=False)
    if image.shape[1] != 1:
        raise ShapeError(f"image must have shape (B, 1, H, W), got {tuple(image.shape)}")
    check_int(max_iter, "max_iter", minimum=0)
    check_positive(tol, "tol", allow_zero=True)
    bad_db = isinstance(window_db, bool) or not isinstance(window_db, int | float)
    if bad_db or not window_db < 0:
        raise OptionError(f"window_db must be negative (dB below the peak), got {window_db!r}")
    check_int(min_window, "min_window", minimum=1)
    img = as_complex(image[:, 0])
    scale = unit_scale(img).reshape(-1, 1, 1)
    img = img / scale  # exact (a power of two): PGA does not depend on the scale
    total = torch.zeros(img.shape[0], img.shape[1], dtype=img.real.dtype, device=img.device)
    iters = torch.zeros(img.shape[0], dtype=torch.int64, device=img.device)
    active = torch.ones(img.shape[0], dtype=torch.bool, device=img.device)
    for it in range(1, max_iter + 1):
        if not bool(active.any()):
            break
        est = _gradient_phase(_azimuth_fft(_window(_centre_shift(img), window_db, min_window)))
        est = est * active[:, None]
        img = _azimuth_ifft(_azimuth_fft(img) * torch.polar(torch.ones_like(est), -est)[..., None])
        total = total + est
        iters = torch.where(active, it, iters)
        active = active & (est.square().mean(-1).sqrt() > tol)
    return AutofocusResult(image=(img * scale).unsqueeze(1), phase=total, iterations=iters)
