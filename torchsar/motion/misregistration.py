"""The look test: an along-track mover is displaced between time sub-aperture images."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar.motion.decision import SAMPLING_ERROR, registration_sigma
from torchsar.motion.focus import fm_correction
from torchsar.motion.looks import LookPlan, look_displacement, look_velocity
from torchsar.motion.params import HANN_BROADENING, SpotlightParams
from torchsar.motion.peaks import intensity
from torchsar.motion.shift import estimate_shift
from torchsar.motion.strips import peak_in_window, robust_pattern, strips

__all__ = ["LOOK_SIGMA_FACTOR", "LookTest", "look_test"]

# Spread of the look-position estimate over its Cramér-Rao bound: z-scores of stationary
# targets in white noise (image SNR 20 dB) had standard deviation 1.4 without this factor,
# 0.9 with it (checked in tests/motion/test_find_movers.py).
LOOK_SIGMA_FACTOR = 1.5


@dataclass(frozen=True)
class LookTest:
    """Per-target result of :func:`look_test` (NaN / False for padding targets).

    Attributes:
        displacement: ``(B, N, K, 2)`` ``(range, azimuth)`` position in look ``k`` minus look 0, m.
        rate: ``(B, N)`` azimuth displacement per second of look time (least-squares slope
            over the looks, stationary pattern removed), m/s.
        velocity: ``(B, N)`` along-track speed giving that rate (:func:`look_velocity`), m/s.
        sigma: ``(B, N)`` standard deviation of ``velocity`` from the registration noise.
        snr: ``(B, N, K)`` peak intensity over the mean background in each look.
        score: ``(B, N)`` ``|velocity| / sigma``.
        mover: bool ``(B, N)`` ``score > n_sigma`` and the target seen in every look
            (``snr >= min_snr``).
    """

    displacement: Tensor
    rate: Tensor
    velocity: Tensor
    sigma: Tensor
    snr: Tensor
    score: Tensor
    mover: Tensor


def _refocused_strips(
    looks: Tensor, plan: LookPlan, params: SpotlightParams, pixel: Tensor, speed: Tensor, half: int
) -> Tensor:
    """``(T, K, S, W)`` look strips around ``pixel (T, 3)`` = (scene, row, col), refocused
    for ``speed (T,)`` about each look's centre time (positions unchanged)."""
    x = strips(looks, pixel[:, 0], pixel[:, 1], half)
    if x.numel() == 0:
        return x
    spec = torch.fft.fft(x, dim=-1)
    w = x.shape[-1]
    phase = torch.stack(
        [fm_correction(params, speed, w, float(t), x.device) for t in plan.time], dim=1
    )
    return torch.fft.ifft(spec * phase[:, :, None, :].to(x.dtype), dim=-1)


def _chips(x: Tensor, peak: Tensor, size: int) -> Tensor:
    """``(T, K, S, size)`` columns ``peak_col - size // 2 ..`` (circular) of strips ``x``."""
    w = x.shape[-1]
    cols = (peak[..., 1:2] + torch.arange(size, device=x.device) - size // 2) % w
    return torch.gather(x, -1, cols[:, :, None, :].expand(-1, -1, x.shape[-2], -1))


def _measure(x: Tensor, peak: Tensor, spacing: tuple[float, float], chip: int) -> Tensor:
    """Sub-pixel ``(range, azimuth)`` position of each look minus look 0, m, ``(T, K, 2)``."""
    amp = _chips(x, peak, chip).abs()
    shift = estimate_shift(amp[:, :1].expand_as(amp), amp, upsample=20).double()
    w = x.shape[-1]
    step = (peak - peak[:, :1]).double()
    step[..., 1] = torch.remainder(step[..., 1] + w / 2, w) - w / 2
    return (step - shift) * torch.tensor(spacing, dtype=torch.float64, device=x.device)


def _slope(values: Tensor, times: Tensor) -> Tensor:
    """Least-squares slope of ``values (..., K)`` against ``times (K,)``."""
    tc = times - times.mean()
    return (values * tc).sum(-1) / (tc * tc).sum()


def look_test(
    looks: Tensor,
    plan: LookPlan,
    params: SpotlightParams,
    *,
    pixel: Tensor,
    valid: Tensor,
    speed: Tensor,
    background: Tensor,
    n_sigma: float = 5.0,
    min_sigma: float = 0.02,
    min_snr: float = 40.0,
    chip: int = 32,
) -> LookTest:
    """Measure each target's displacement between looks and test it against the stationary one.

    Each look is refocused about its own centre time for ``speed`` (the focus test's
    estimate, or 0), which compacts a fast mover without moving it; the target is searched
    within three look-resolution cells of where ``speed`` predicts it and its sub-pixel
    position relative to look 0 is measured by cross-correlating amplitude chips
    (:func:`~torchsar.motion.shift.estimate_shift`). The azimuth positions give a displacement
    rate (least-squares slope against look time); the median rate over >= 3 targets is the
    stationary pattern. The rate's standard deviation comes from the Cramér-Rao bound of each
    look's peak position at its SNR (:func:`~torchsar.motion.decision.registration_sigma`,
    times :data:`LOOK_SIGMA_FACTOR` for the estimator's excess over the bound) plus 0.03
    pixel of sampling error; a mover exceeds ``n_sigma`` of it and is seen in every look
    with ``snr >= min_snr`` (below that, peaks are noise-dominated and the bound does not
    hold).

    Args:
        looks: complex ``(B, K, H, W)`` look images (:func:`~torchsar.motion.looks.look_images`).
        plan: the looks' :class:`~torchsar.motion.looks.LookPlan`.
        params: the system.
        pixel: long ``(B, N, 2)`` target pixel in the full image.
        valid: bool ``(B, N)`` real targets.
        speed: ``(B, N)`` along-track speed (m/s) used to refocus and predict.
        background: ``(B, K)`` mean background intensity of each look.
        n_sigma: decision threshold.
        min_sigma: floor of the velocity sigma (m/s).
        min_snr: smallest look SNR (peak over mean background intensity) tested.
        chip: chip width in columns for the cross-correlation.

    Returns:
        :class:`LookTest`.
    """
    b, n = valid.shape
    k, w = looks.shape[1], looks.shape[-1]
    dy, dx = params.image_extent[0] / looks.shape[-2], params.image_extent[1] / w
    res = (
        HANN_BROADENING * params.geometry.range_resolution,
        HANN_BROADENING * params.geometry.cross_range_resolution,
    )
    res_look = (res[0], res[1] * params.geometry.pulses / float(plan.stop[0] - plan.start[0]))
    half = max(2, math.ceil(res[0] / dy))
    idx = torch.arange(b, device=pixel.device)[:, None].expand(b, n)
    flat = torch.stack([idx, pixel[..., 0], pixel[..., 1]], -1).reshape(-1, 3).clamp(min=0)
    v = speed.reshape(-1).nan_to_num()
    x = _refocused_strips(looks, plan, params, flat, v, half)
    times = plan.time.to(x.device)
    predicted = flat[:, 2:3] + torch.round(look_displacement(v[:, None], times, params) / dx).long()
    value, peak = peak_in_window(intensity(x), predicted, max(2, math.ceil(3 * res_look[1] / dx)))
    disp = _measure(x, peak, (dy, dx), chip)
    snr = value.double() / background.double().repeat_interleave(n, 0).clamp(min=1e-300)
    crlb = LOOK_SIGMA_FACTOR * registration_sigma(snr, res_look)[..., 1]
    sig_x = crlb.hypot(torch.tensor(SAMPLING_ERROR * dx))
    tc = times - times.mean()
    sig_rate = torch.sqrt((sig_x * tc / (tc * tc).sum()).square().sum(-1))
    rate = _slope(disp[..., 1], times).reshape(b, n)
    rate = rate - robust_pattern(rate, valid)
    velocity = look_velocity(rate, params)
    dvdr = 1 / (2 - 2 * velocity / params.track.platform_speed)
    sigma = (sig_rate.reshape(b, n) * dvdr.abs()).clamp(min=min_sigma)
    score = velocity.abs() / sigma
    nan = torch.tensor(float("nan"), dtype=torch.float64, device=x.device)
    m = valid[..., None, None]
    return LookTest(
        torch.where(m, disp.reshape(b, n, k, 2), nan),
        *(torch.where(valid, t, nan) for t in (rate, velocity, sigma)),
        torch.where(valid[..., None], snr.reshape(b, n, k), nan),
        torch.where(valid, score, nan),
        valid & (score > n_sigma) & (snr.reshape(b, n, k).amin(-1) >= min_snr),
    )
