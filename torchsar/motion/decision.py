"""The mover decision: displacements inconsistent with the stationary pattern."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar._checks import check_pairs, check_positive
from torchsar.errors import InputTypeError, InputValueError, ShapeError

__all__ = ["SAMPLING_ERROR", "MoverDecision", "detect_movers", "registration_sigma"]

SAMPLING_ERROR = 0.03  # registration error of sampled chips (pixels, 1/upsample quantisation)


@dataclass(frozen=True)
class MoverDecision:
    """Output of :func:`detect_movers`.

    Attributes:
        pattern: ``(B, P, 2)`` the stationary displacement pattern (median over targets).
        residual: ``(B, N, P, 2)`` displacement minus pattern (NaN where missing).
        sigma: ``(B, N, P, 2)`` measurement standard deviation used for each residual.
        score: ``(B, N)`` ``max |residual| / sigma`` over subpatches and axes (NaN if the
            target was measured in fewer than two images).
        mover: bool ``(B, N)`` ``score > n_sigma``.
    """

    pattern: Tensor
    residual: Tensor
    sigma: Tensor
    score: Tensor
    mover: Tensor


def registration_sigma(snr: Tensor, resolution: tuple[float, float]) -> Tensor:
    """Cramér-Rao standard deviation of a peak-position estimate, ``(..., 2)`` in m.

    For a response of resolution ``rho`` (flat spectrum of width ``1 / rho``) and peak
    signal-to-noise ratio ``snr`` the position CRLB is ``sqrt(3) rho / (pi sqrt(2 snr))``.

    Examples:
        >>> snr = torch.tensor([100.0], dtype=torch.float64)
        >>> registration_sigma(snr, (1.0, 0.5)).round(decimals=4).tolist()
        [[0.039, 0.0195]]
    """
    k = math.sqrt(3) / (math.pi * torch.sqrt(2 * snr.clamp(min=1e-12)))
    return torch.stack([k * resolution[0], k * resolution[1]], dim=-1)


def detect_movers(
    displacements: Tensor,
    *,
    sigma: Tensor | float | None = None,
    n_sigma: float = 5.0,
    min_sigma: float = 0.0,
) -> MoverDecision:
    """Flag targets whose displacement between subpatch images departs from the stationary one.

    Stationary targets share one displacement pattern; it is estimated per scene, subpatch
    and axis as the median over targets (robust to a minority of movers, needs >= 3 targets
    to outvote one mover). A target is a mover when some residual exceeds ``n_sigma``
    measurement standard deviations.

    Args:
        displacements: ``(B, N, P, 2)`` displacement of target ``n`` in subpatch image ``p``
            relative to the reference image, in m (NaN = not measured). Padding targets are
            all-NaN.
        sigma: measurement standard deviation per residual (broadcastable to
            ``displacements``, e.g. from :func:`registration_sigma`; finite and > 0 where a
            displacement is measured), or ``None`` to estimate
            it from the residuals (``1.4826 * MAD`` pooled over targets, subpatches and axes).
        n_sigma: decision threshold in standard deviations.
        min_sigma: floor on ``sigma`` (model error not covered by the noise, in m).

    Returns:
        :class:`MoverDecision`.

    Raises:
        InputTypeError, ShapeError, OptionError: bad input (``N = 0`` targets is valid:
            an empty decision).
        InputValueError: a ``sigma`` that is not finite and positive.

    Shape:
        ``(B, N, P, 2)`` -> ``(B, N)``.

    References:
        Yusufoglu & Kartal, seed paper (subpatch displacement test); Rousseeuw & Croux,
        "Alternatives to the median absolute deviation", JASA 88(424), 1993,
        doi:10.1080/01621459.1993.10476408.

    Examples:
        >>> d = torch.zeros(1, 4, 4, 2); d[0, 3, 1:, 0] = torch.tensor([0.5, -0.4, 0.6])
        >>> detect_movers(d, sigma=0.05).mover.tolist()
        [[False, False, False, True]]
    """
    d = check_pairs(
        displacements,
        "displacements",
        ndim=4,
        axes="(B, N, P, 2) (scene, target, subpatch, (range, azimuth))",
    )
    n_sigma = check_positive(n_sigma, "n_sigma")
    min_sigma = check_positive(min_sigma, "min_sigma", allow_zero=True)
    given = None if sigma is None else _check_sigma(sigma, d)
    if d.shape[1] == 0:  # no targets: an empty decision, the pattern undefined
        pattern = torch.full((d.shape[0], *d.shape[2:]), torch.nan, dtype=d.dtype, device=d.device)
    else:
        pattern = d.nanmedian(dim=1).values
    residual = d - pattern[:, None]
    sig = _pooled_mad(residual)[:, None, None, None].expand_as(residual) if given is None else given
    sig = sig.clamp(min=max(min_sigma, torch.finfo(d.dtype).tiny))
    z = (residual / sig).abs().flatten(2)
    measured = (~torch.isnan(d[..., 0])).sum(-1) >= 2
    score = torch.where(measured, torch.nan_to_num(z, nan=-1.0).amax(-1), torch.nan)
    return MoverDecision(pattern, residual, sig, score, torch.nan_to_num(score, nan=0.0) > n_sigma)


def _check_sigma(sigma: object, d: Tensor) -> Tensor:
    """``sigma`` as a tensor broadcast to ``d``: finite and > 0 wherever ``d`` is measured."""
    if isinstance(sigma, bool) or not isinstance(sigma, Tensor | int | float):
        raise InputTypeError(f"sigma must be a number, a tensor or None, got {sigma!r:.60}")
    sig = torch.as_tensor(sigma, dtype=d.dtype, device=d.device)
    try:
        sig = sig.expand_as(d)
    except RuntimeError:
        raise ShapeError(
            f"sigma must broadcast to displacements {tuple(d.shape)}, got {tuple(sig.shape)}"
        ) from None
    bad = ~(torch.isfinite(sig) & (sig > 0)) & ~(torch.isnan(sig) & torch.isnan(d))
    if bad.any():
        raise InputValueError(
            f"sigma must be finite and > 0 (a standard deviation), got {float(sig[bad][0])!r}"
        )
    return sig


def _pooled_mad(residual: Tensor) -> Tensor:
    """``1.4826 * median |r|`` per scene over the non-reference residuals (``(B,)``)."""
    r = residual[:, :, 1:].flatten(1).abs()
    if r.shape[1] == 0:
        return torch.full((r.shape[0],), torch.nan, dtype=r.dtype, device=r.device)
    return 1.4826 * r.nanmedian(dim=1).values
