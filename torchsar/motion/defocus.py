"""The focus test: a mover's azimuth FM rate differs, so it focuses best at a non-zero speed."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar.motion.focus import fm_correction, focus_step, speed_bank
from torchsar.motion.params import HANN_BROADENING, SpotlightParams
from torchsar.motion.peaks import intensity
from torchsar.motion.strips import peak_in_window, robust_pattern

__all__ = ["FOCUS_SIGMA_FACTOR", "FocusTest", "focus_curve", "focus_test"]

# sigma_v = FOCUS_SIGMA_FACTOR * w / sqrt(snr), w the Gaussian width (m/s) of the focus curve.
# On stationary targets in white noise (image SNR 20-30 dB) the resulting z-scores spread
# with a standard deviation of 0.6-0.7, so 1.0 is conservative (checked in
# tests/motion/test_find_movers.py::TestAlongTrackMovers::test_uncertainty_is_honest).
FOCUS_SIGMA_FACTOR = 1.0


@dataclass(frozen=True)
class FocusTest:
    """Per-target result of :func:`focus_test` (all ``(B, N)``; NaN / False for padding).

    Attributes:
        velocity: along-track speed (m/s) that focuses the target best, minus the pattern.
        sigma: its standard deviation (m/s) from the focus-curve width and the SNR.
        gain: peak intensity at the best speed over the peak at speed 0 (>= 1).
        snr: best-focused peak intensity over the mean background.
        score: ``|velocity| / sigma``.
        mover: bool ``score > n_sigma``.
    """

    velocity: Tensor
    sigma: Tensor
    gain: Tensor
    snr: Tensor
    score: Tensor
    mover: Tensor


def focus_curve(
    strips: Tensor,
    params: SpotlightParams,
    speeds: Tensor,
    column: Tensor,
    half: int,
    *,
    ranges: Tensor | None = None,
) -> Tensor:
    """Peak intensity near ``column`` of each strip refocused for each speed, ``(..., Q)``.

    Args:
        strips: complex ``(..., S, W)`` rows of a full-aperture image around each target.
        params: the system.
        speeds: ``(Q,)`` along-track speeds (m/s), or ``(..., Q)`` per target.
        column: long ``(...)`` target column.
        half: half-width (columns) of the window searched for the peak.
        ranges: optional ``(...)`` range offset of each target (m): each strip is refocused
            at its own slant range.
    """
    if strips.numel() == 0:
        return torch.zeros(*strips.shape[:-2], speeds.shape[-1], dtype=torch.float64)
    spectrum = torch.fft.fft(strips, dim=-1)[..., None, :, :]
    r = None if ranges is None else ranges[..., None]
    out = []
    for i in range(0, speeds.shape[-1], 16):
        phase = fm_correction(
            params, speeds[..., i : i + 16], strips.shape[-1], 0.0, strips.device, ranges=r
        )
        power = intensity(torch.fft.ifft(spectrum * phase[..., None, :].to(strips.dtype), dim=-1))
        out.append(peak_in_window(power, column[..., None], half)[0])
    return torch.cat(out, dim=-1).double()


def _vertex(curve: Tensor, speeds: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Parabolic vertex of ``log curve`` around its maximum: ``(speed, width, peak)``.

    ``speeds`` is ``(Q,)`` or ``(..., Q)``, evenly spaced.
    """
    q = speeds.shape[-1]
    i = curve.argmax(-1).clamp(1, q - 2)[..., None]
    logc = curve.clamp(min=1e-300).log()
    a, b, c = (torch.gather(logc, -1, i + k)[..., 0] for k in (-1, 0, 1))
    grid = speeds.to(curve).expand_as(curve)
    h = grid[..., 1] - grid[..., 0]
    denom = (a - 2 * b + c).clamp(max=-1e-12)
    offset = (0.5 * (a - c) / denom).clamp(-1, 1)
    width = h / torch.sqrt(-denom)  # Gaussian std of the intensity curve, m/s
    peak = torch.exp(b - 0.25 * (a - c) * offset)
    return torch.gather(grid, -1, i)[..., 0] + offset * h, width, peak


def _refine(strips, params, speed, step, column, half, ranges) -> tuple[Tensor, Tensor]:
    """Vertex ``(speed, peak)`` of the focus curve sampled again at ``step / 4`` around
    ``speed``: the coarse vertex is biased by up to ~6 % of ``step`` where the curve is
    not log-parabolic, the fine one ~16 times less."""
    fine = speed[..., None] + (step / 4) * torch.tensor([-1.0, 0.0, 1.0]).to(speed)
    curve = focus_curve(strips, params, fine, column, half, ranges=ranges)
    refined, _, peak = _vertex(curve, fine)
    return refined, peak


def focus_test(
    strips: Tensor,
    params: SpotlightParams,
    *,
    column: Tensor,
    valid: Tensor,
    background: Tensor,
    max_speed: float = 16.0,
    n_sigma: float = 5.0,
    min_sigma: float = 0.0,
    ranges: Tensor | None = None,
    reference: Tensor | None = None,
) -> FocusTest:
    """Best-focusing along-track speed of each target and whether it departs from zero.

    Each target's full-aperture strip is refocused over a grid of speeds (half of
    :func:`~torchsar.motion.focus.focus_step`); the peak intensity near the target traces a
    focus curve whose maximum (parabolic vertex of its logarithm) is the speed estimate.
    Stationary targets focus at 0 (the median over >= 3 targets is subtracted, absorbing a
    common FM-rate error); a mover is a target whose speed exceeds ``n_sigma`` standard
    deviations, ``sigma = max(FOCUS_SIGMA_FACTOR * w / sqrt(snr), min_sigma)`` with ``w`` the
    curve's width.

    Args:
        strips: complex ``(B, N, S, W)`` full-aperture rows around each target.
        params: the system.
        column: long ``(B, N)`` target column.
        valid: bool ``(B, N)`` real targets (False = padding).
        background: ``(B,)`` mean background intensity of each scene's image.
        max_speed: largest speed searched (m/s).
        n_sigma: decision threshold.
        min_sigma: optional floor of sigma (m/s; default none).
        ranges: ``(B, N)`` range offset of each target from the scene centre (m): the bank
            is applied at each target's own slant range (default: the scene centre's).
        reference: bool ``(B, N)`` targets whose median defines the stationary pattern
            (default ``valid``).

    Returns:
        :class:`FocusTest`.
    """
    step = focus_step(params) / 2
    speeds = speed_bank(max_speed + step, step).to(strips.device)
    res_px = (
        HANN_BROADENING
        * params.geometry.cross_range_resolution
        * strips.shape[-1]
        / params.image_extent[1]
    )
    half = max(2, math.ceil(2 * res_px))
    curve = focus_curve(strips, params, speeds, column, half, ranges=ranges)
    speed, width, _ = _vertex(curve, speeds)
    speed, peak = _refine(strips, params, speed, step, column, half, ranges)
    zero = curve[..., speeds.numel() // 2]
    snr = peak / background.to(peak)[:, None].clamp(min=1e-300)
    speed = speed - robust_pattern(speed, valid if reference is None else reference & valid)
    sigma = (FOCUS_SIGMA_FACTOR * width / snr.clamp(min=1e-12).sqrt()).clamp(min=min_sigma)
    score = speed.abs() / sigma
    nan = torch.tensor(float("nan"), dtype=speed.dtype, device=speed.device)
    fields = [torch.where(valid, x, nan) for x in (speed, sigma, peak / zero, snr, score)]
    return FocusTest(*fields, mover=valid & (score > n_sigma))
