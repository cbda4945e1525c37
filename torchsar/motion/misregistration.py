"""The look test: a mover is displaced between time sub-aperture images, in azimuth or range.

An along-track mover moves in azimuth between looks, ``(2 v_a - v_a^2 / V) dt`` in the
image (:func:`~torchsar.motion.looks.look_displacement`); a Doppler-folded radial mover
walks in range, ``-k lambda PRF dt / 2`` (:mod:`torchsar.motion.folds`); a stationary
target does neither. One measurement gives both: each target's look strips are refocused
for its along-track speed hypothesis and unwalked for its fold hypothesis (about each
look's own centre time, so the target is compacted where it is, not moved), the target is
searched where the hypotheses put it, and its sub-pixel ``(range, azimuth)`` position
relative to look 0 is measured by cross-correlating amplitude chips.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar.motion.decision import SAMPLING_ERROR, registration_sigma
from torchsar.motion.focus import fm_correction
from torchsar.motion.folds import walk_correction
from torchsar.motion.looks import LookPlan, look_displacement, look_velocity
from torchsar.motion.params import HANN_BROADENING, SpotlightParams
from torchsar.motion.peaks import intensity
from torchsar.motion.shift import estimate_shift
from torchsar.motion.strips import peak_in_box, robust_pattern, strips

__all__ = ["INTERFERENCE_SIGMA", "LOOK_BALANCE", "LOOK_SIGMA_FACTOR", "LookTest", "look_test"]

# Spread of the look-position estimate over its Cramér-Rao bound: with it, stationary
# targets of the seeded random scenes (28 dB) have look-speed z-scores of rms 0.8 and range
# walk z-scores of rms 0.65 (tests/motion/test_find_movers.py::TestRandomScenes).
LOOK_SIGMA_FACTOR = 1.5
# Position error (look-resolution cells) per unit relative amplitude of other targets'
# streaks at the target's look position. Measured on 137 along-track movers of 96 random
# scenes: without it, movers on a bright neighbour's streak were off by 6-8 sigma (rms z
# 1.31); with 0.1-0.5 the rms is 0.96-1.0 and the largest 3.1; 0.25 is used.
INTERFERENCE_SIGMA = 0.25
# A target seen in every look has about the same peak in each; a look whose peak is more
# than this many times another's has caught a neighbour (the measurement is not trusted).
LOOK_BALANCE = 4.0
CHIP = (8, 12)  # (rows, columns) of the amplitude chips cross-correlated: the main lobe


@dataclass(frozen=True)
class LookTest:
    """Per-target result of :func:`look_test` (NaN / False for padding targets).

    Attributes:
        displacement: ``(B, N, K, 2)`` ``(range, azimuth)`` position in look ``k`` minus look 0, m.
        rate: ``(B, N)`` azimuth displacement per second of look time (least-squares slope
            over the looks, stationary pattern removed), m/s.
        velocity: ``(B, N)`` along-track speed giving that rate at the target's own range
            (:func:`~torchsar.motion.looks.look_velocity`), m/s.
        sigma: ``(B, N)`` standard deviation of ``velocity``.
        snr: ``(B, N, K)`` peak intensity over the mean background in each look.
        score: ``(B, N)`` ``|velocity| / sigma``.
        mover: bool ``(B, N)`` ``score > n_sigma`` and ``seen``.
        walk: ``(B, N)`` range displacement per second of look time (slope, stationary
            pattern removed), m/s: ``-k lambda PRF / 2`` for a target of fold ``k``.
        walk_sigma: ``(B, N)`` its standard deviation.
        interference: ``(B, N, K)`` the relative amplitude of other targets' streaks used
            (0 when not given).
        seen: bool ``(B, N)`` the target seen in every look (``snr >= min_snr``, peaks
            within :data:`LOOK_BALANCE` of each other): the rates are trusted.
    """

    displacement: Tensor
    rate: Tensor
    velocity: Tensor
    sigma: Tensor
    snr: Tensor
    score: Tensor
    mover: Tensor
    walk: Tensor
    walk_sigma: Tensor
    interference: Tensor
    seen: Tensor


def _strip_half(params: SpotlightParams, plan: LookPlan, max_fold: int, dy: float) -> int:
    """Half-height (rows) of the look strips: the walk of ``max_fold + 1`` folds to the
    furthest look, two resolution cells of search and half a chip."""
    walk = (max_fold + 1) * params.geometry.blind_speed * float(plan.time.abs().max())
    search = 2 * HANN_BROADENING * params.geometry.range_resolution
    return math.ceil((walk + search) / dy) + CHIP[0] // 2


def _corrected_strips(looks, plan, params, flat, speed, fold, ranges, half, dy) -> Tensor:
    """``(T, K, S, W)`` look strips around ``flat (T, 3)`` = (scene, row, col), refocused for
    ``speed`` and unwalked for ``fold`` about each look's centre time (positions unchanged)."""
    x = strips(looks, flat[:, 0], flat[:, 1], half)
    if x.numel() == 0:
        return x
    moving = (speed != 0).nonzero().flatten()
    if moving.numel():
        phase = torch.stack(
            [
                fm_correction(
                    params, speed[moving], x.shape[-1], float(t), x.device, ranges=ranges[moving]
                )
                for t in plan.time
            ],
            dim=1,
        )
        spec = torch.fft.fft(x[moving], dim=-1)
        x[moving] = torch.fft.ifft(spec * phase[:, :, None, :].to(x.dtype), dim=-1)
    folded = (fold != 0).nonzero().flatten()
    if folded.numel():
        factor = torch.stack(
            [
                walk_correction(params, fold[folded], x.shape[-2:], dy, float(t), x.device)
                for t in plan.time
            ],
            dim=1,
        )
        x[folded] = torch.fft.ifft2(torch.fft.fft2(x[folded]) * factor.to(x.dtype))
    return x


def _chips(x: Tensor, peak: Tensor) -> Tensor:
    """``(T, K, rows, cols)`` chips of strips ``x`` around ``peak (T, K, 2)`` (circular)."""
    s, w = x.shape[-2:]
    rows = (peak[..., :1] + torch.arange(CHIP[0], device=x.device) - CHIP[0] // 2) % s
    cols = (peak[..., 1:] + torch.arange(CHIP[1], device=x.device) - CHIP[1] // 2) % w
    t = torch.arange(x.shape[0], device=x.device)[:, None, None, None]
    k = torch.arange(x.shape[1], device=x.device)[None, :, None, None]
    return x[t, k, rows[..., :, None], cols[..., None, :]]


def _measure(x: Tensor, peak: Tensor, spacing: tuple[float, float]) -> Tensor:
    """Sub-pixel ``(range, azimuth)`` position of each look minus look 0, m, ``(T, K, 2)``."""
    amp = _chips(x, peak).abs()
    shift = estimate_shift(amp[:, :1].expand_as(amp), amp, upsample=20).double()
    w = x.shape[-1]
    step = (peak - peak[:, :1]).double()
    step[..., 1] = torch.remainder(step[..., 1] + w / 2, w) - w / 2
    return (step - shift) * torch.tensor(spacing, dtype=torch.float64, device=x.device)


def _slope_sigma(sig_x: Tensor, times: Tensor) -> Tensor:
    """Standard deviation of the least-squares slope for position sigmas ``(..., K)``."""
    tc = times - times.mean()
    return torch.sqrt((sig_x * tc / (tc * tc).sum()).square().sum(-1))


def _slope(values: Tensor, times: Tensor) -> Tensor:
    """Least-squares slope of ``values (..., K)`` against ``times (K,)``."""
    tc = times - times.mean()
    return (values * tc).sum(-1) / (tc * tc).sum()


def _resolution(params: SpotlightParams, plan: LookPlan) -> tuple[float, float]:
    """Hann-broadened ``(range, azimuth)`` resolution of one look, m."""
    pulses = float(plan.stop[0] - plan.start[0])
    return (
        HANN_BROADENING * params.geometry.range_resolution,
        HANN_BROADENING * params.geometry.cross_range_resolution * params.geometry.pulses / pulses,
    )


def _search_box(params, res, spacing, times, fold, max_fold) -> tuple[tuple[int, int], Tensor]:
    """Search half-widths around the predicted pixel: 1.5 look-resolution cells in azimuth,
    one in range, plus one fold's walk in range where the bank's fold may be off (it has no
    folds, or the target is at its last one). Returns the widest box and the rows per target."""
    walk = params.geometry.blind_speed * float(times.abs().max())
    near = math.ceil(res[0] / spacing[0])
    far = math.ceil((res[0] + walk) / spacing[0])
    open_ended = (
        (fold.abs() >= max_fold) if max_fold > 0 else torch.ones_like(fold, dtype=torch.bool)
    )
    rows = torch.where(open_ended, far, near)[:, None].expand(-1, times.numel())
    return (far, max(2, math.ceil(1.5 * res[1] / spacing[1]))), rows


def _predicted(flat, speed, fold, ranges, times, params, spacing, half) -> Tensor:
    """Long ``(T, K, 2)`` strip pixel where the hypotheses put each target in each look."""
    dx = look_displacement(speed[:, None], times, params, ranges=ranges[:, None])
    dy = -fold[:, None].double() * params.geometry.blind_speed * times
    row = half + torch.round(dy / spacing[0]).long()
    col = flat[:, 2:3] + torch.round(dx / spacing[1]).long()
    return torch.stack([row, col], -1)


def look_test(
    looks: Tensor,
    plan: LookPlan,
    params: SpotlightParams,
    *,
    pixel: Tensor,
    valid: Tensor,
    speed: Tensor,
    background: Tensor,
    fold: Tensor | None = None,
    max_fold: int = 0,
    interference: Tensor | None = None,
    n_sigma: float = 5.0,
    min_sigma: float = 0.0,
    min_snr: float = 40.0,
) -> LookTest:
    """Measure each target's displacement between looks and test it against the stationary one.

    Each look is refocused about its own centre time for ``speed`` (the focus test's
    estimate, or 0) and unwalked for ``fold`` (the motion bank's, or 0), which compacts a
    mover without moving it; the target is searched within one resolution cell in range
    (plus one fold's walk where the fold may be off: no bank folds, or the bank's last one)
    and 1.5 look-resolution cells in azimuth of where the hypotheses put it, and its
    sub-pixel position relative to look 0 is measured by cross-correlating amplitude chips
    of the main lobe (:func:`~torchsar.motion.shift.estimate_shift`). The
    positions give a displacement rate per axis (least-squares slope against look time);
    the median rate over >= 3 targets is the stationary pattern. Each rate's standard
    deviation comes from the Cramér-Rao bound of each look's peak position at its SNR
    (:func:`~torchsar.motion.decision.registration_sigma`, times
    :data:`LOOK_SIGMA_FACTOR` for the estimator's excess over the bound) and 0.03 pixel of
    sampling error, plus the interference of other targets' streaks where given. The azimuth
    rate is converted to speed at the target's own slant range; a mover exceeds ``n_sigma``
    of it and is seen in every look with ``snr >= min_snr`` (below that, peaks are
    noise-dominated and the bound does not hold) and peaks within :data:`LOOK_BALANCE` of
    each other (a look whose peak is much brighter has caught a neighbour).

    Args:
        looks: complex ``(B, K, H, W)`` look images (:func:`~torchsar.motion.looks.look_images`).
        plan: the looks' :class:`~torchsar.motion.looks.LookPlan`.
        params: the system.
        pixel: long ``(B, N, 2)`` target pixel in the full image.
        valid: bool ``(B, N)`` real targets.
        speed: ``(B, N)`` along-track speed (m/s) used to refocus and predict.
        background: ``(B, K)`` mean background intensity of each look.
        fold: long ``(B, N)`` Doppler fold used to unwalk and predict (default 0).
        max_fold: largest ``|fold|`` expected (sets the strip height).
        interference: ``(B, N, K)`` amplitude of other targets' streaks at each target in
            each look, relative to its own
            (:func:`~torchsar.motion.streaks.look_interference`): adds
            ``INTERFERENCE_SIGMA * interference`` look-resolution cells to each look's
            position sigma.
        n_sigma: decision threshold.
        min_sigma: optional floor of the velocity sigma (m/s; default none).
        min_snr: smallest look SNR (peak over mean background intensity) tested.

    Returns:
        :class:`LookTest`.
    """
    b, n = valid.shape
    k, h, w = looks.shape[1:]
    spacing = (params.image_extent[0] / h, params.image_extent[1] / w)
    res = _resolution(params, plan)
    half = _strip_half(params, plan, max_fold, spacing[0])
    idx = torch.arange(b, device=pixel.device)[:, None].expand(b, n)
    flat = torch.stack([idx, pixel[..., 0], pixel[..., 1]], -1).reshape(-1, 3).clamp(min=0)
    v = speed.reshape(-1).nan_to_num()
    kf = torch.zeros_like(flat[:, 0]) if fold is None else fold.reshape(-1).to(flat)
    ranges = (flat[:, 1].double() - h // 2) * spacing[0]
    x = _corrected_strips(looks, plan, params, flat, v, kf, ranges, half, spacing[0])
    times = plan.time.to(x.device)
    predicted = _predicted(flat, v, kf, ranges, times, params, spacing, half)
    box, rows = _search_box(params, res, spacing, times, kf, max_fold)
    value, peak = peak_in_box(intensity(x), predicted, box, rows=rows)
    disp = _measure(x, peak, spacing)
    snr = value.double() / background.double().repeat_interleave(n, 0).clamp(min=1e-300)
    crlb = LOOK_SIGMA_FACTOR * registration_sigma(snr, res)
    sampling = SAMPLING_ERROR * torch.tensor(spacing, dtype=torch.float64)
    sig_pos = crlb.hypot(sampling.to(crlb.device))  # (T, K, 2)
    if interference is not None:
        extra = INTERFERENCE_SIGMA * interference.reshape(-1, interference.shape[-1])[..., None]
        sig_pos = sig_pos.hypot(extra.to(sig_pos) * torch.tensor(res).to(sig_pos))
    rates = torch.stack([_slope(disp[..., a], times) for a in (0, 1)], -1).reshape(b, n, 2)
    rates = rates - robust_pattern(rates, valid)
    sig_rates = torch.stack([_slope_sigma(sig_pos[..., a], times) for a in (0, 1)], -1)
    crowd = torch.zeros(b, n, k, dtype=torch.float64) if interference is None else interference
    return _result(
        disp,
        rates,
        sig_rates.reshape(b, n, 2),
        snr,
        crowd.to(snr),
        valid,
        params,
        ranges,
        n_sigma,
        min_sigma,
        min_snr,
    )


def _result(disp, rates, sig_rates, snr, crowd, valid, params, ranges, n_sigma, min_sigma, min_snr):
    """:class:`LookTest` from the per-axis rates and their sigmas (padding -> NaN / False)."""
    b, n = valid.shape
    r = ranges.reshape(b, n)
    velocity = look_velocity(rates[..., 1], params, ranges=r)
    scale = 1 + r / params.track.scene_range
    dvdr = scale / (2 - 2 * velocity / params.track.platform_speed)
    sigma = (sig_rates[..., 1] * dvdr.abs()).clamp(min=min_sigma)
    score = velocity.abs() / sigma
    snr = snr.reshape(b, n, crowd.shape[-1])
    nan = torch.tensor(float("nan"), dtype=torch.float64, device=disp.device)
    seen = valid & (snr.amin(-1) >= min_snr) & (snr.amax(-1) <= LOOK_BALANCE * snr.amin(-1))
    mover = seen & (score > n_sigma)
    return LookTest(
        torch.where(valid[..., None, None], disp.reshape(b, n, crowd.shape[-1], 2), nan),
        *(torch.where(valid, t, nan) for t in (rates[..., 1], velocity, sigma)),
        torch.where(valid[..., None], snr, nan),
        torch.where(valid, score, nan),
        mover,
        *(torch.where(valid, t, nan) for t in (rates[..., 0], sig_rates[..., 0])),
        torch.where(valid[..., None], crowd, nan),
        seen,
    )
