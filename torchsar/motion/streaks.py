"""Streaks: a point target seen in an image corrected for the wrong motion.

A target of along-track speed ``v_j`` and Doppler fold ``k_j`` in an image refocused for
``v_i`` and unwalked for ``k_i`` (about time ``t_c``) is not a point but a streak: the slow
time ``t`` of its aperture lands at ``(t - t_c) d`` from where it focuses,
``d = (-(k_j - k_i) lambda PRF / 2, 2 (v_j - v_i))`` m/s in ``(range, azimuth)``. By
stationary phase its intensity there is ``I_j (w(t) tau / (T w_mean))^2``: ``w`` the
aperture taper, ``T`` the aperture, ``tau`` the coherent time of one position:
``1 / sqrt(alpha)`` for the azimuth chirp rate ``alpha = 4 V |v_j - v_i| / (lambda R0)`` of
the speed error, ``2 rho_r / |d_r|`` for a range walk through the range resolution
``rho_r``, ``(tau_a^-2 + tau_r^-2)^-1/2`` for both (checked against simulated streaks to
within a factor 1.4 on the streak, tests/motion/test_streaks.py). Two uses: peaks that are
only a brighter target's streak are ghosts (:func:`~torchsar.motion.targets.smear_ghosts`),
and a target whose look position lies on a neighbour's streak is measured with that
interference (:func:`look_interference`).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar.motion.looks import LookPlan, look_displacement
from torchsar.motion.params import HANN_BROADENING, SpotlightParams

__all__ = ["look_interference", "streak_level"]


def streak_level(
    delta: Tensor,
    drift: Tensor,
    params: SpotlightParams,
    *,
    aperture: float | None = None,
    speed_step: float = 0.0,
    window: str = "hann",
) -> Tensor:
    """Intensity, relative to the focused peak, of a streak at ``delta`` from its centre.

    Args:
        delta: ``(..., 2)`` offset ``(range, azimuth)`` in m from where the target focuses.
        drift: ``(..., 2)`` the streak's drift ``d`` in m/s (0: no streak, level 0).
        params: the system.
        aperture: aperture time ``T`` of the image in s (default the full aperture).
        speed_step: uncertainty of the speeds behind ``drift`` (m/s): widens the streak by
            ``speed_step |t|`` in azimuth.
        window: the aperture taper, ``"hann"`` or ``"none"``.

    Returns:
        float64 ``(...)``: 0 off the streak (beyond one resolution cell of the segment; in
        azimuth the cell a walk's dwell leaves), else the stationary-phase level, taken one
        coherent time towards the centre.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> p = SpotlightParams.from_system()
        >>> d = torch.tensor([[0.0, 8.0]], dtype=torch.float64)  # 4 m/s speed error
        >>> [round(float(streak_level(x, d, p)), 3) for x in (torch.tensor([[0.0, 5.0]]),
        ...                                                   torch.tensor([[3.0, 5.0]]))]
        [0.043, 0.0]
    """
    geo = params.geometry
    total = geo.aperture_time if aperture is None else aperture
    half = total / 2
    rho = HANN_BROADENING * torch.tensor(
        [geo.range_resolution, geo.cross_range_resolution * geo.aperture_time / total],
        dtype=torch.float64,
    )
    delta, drift = delta.double(), drift.double()
    dd = drift.square().sum(-1)
    t = ((delta * drift).sum(-1) / dd.clamp(min=1e-12)).clamp(-half, half)
    res = (delta - drift * t[..., None]).abs()
    speed_error = drift[..., 1].abs() / 2
    alpha = (
        4 * params.track.platform_speed * speed_error / (geo.wavelength * params.track.scene_range)
    )
    walk = drift[..., 0].abs() / (2 * geo.range_resolution)  # 1 / tau_r
    tau = (alpha + walk.square()).clamp(min=1e-12).rsqrt()
    dwell = (total * walk).clamp(min=1.0)  # azimuth resolution lost to a range walk
    near = (res[..., 0] <= rho[0]) & (res[..., 1] <= rho[1] * dwell + speed_step * t.abs())
    t_eff = (t.abs() - tau).clamp(min=0)
    if window == "none":
        taper, mean = torch.ones_like(t_eff), 1.0
    else:
        taper, mean = torch.cos(math.pi * t_eff / total).square(), 0.5
    level = (taper * tau / (total * mean)).square().clamp(max=1.0)
    return torch.where(near & (dd > 0), level, torch.zeros_like(level))


def _look_positions(position: Tensor, speed: Tensor, fold: Tensor, time: float, params) -> Tensor:
    """``(B, N, 2)`` position of each target in the look centred at ``time`` (m)."""
    rng = position[..., 0] - fold.double() * params.geometry.blind_speed * time
    azi = position[..., 1] + look_displacement(speed, time, params, ranges=position[..., 0])
    return torch.stack([rng, azi], -1)


def look_interference(
    position: Tensor,
    speed: Tensor,
    fold: Tensor,
    intensity: Tensor,
    valid: Tensor,
    plan: LookPlan,
    params: SpotlightParams,
    *,
    window: str = "hann",
) -> Tensor:
    """Relative amplitude of the neighbours' streaks at each target in each corrected look.

    Look ``k`` is refocused for the target's own speed and unwalked for its fold about the
    look's centre time (as the look test does); every other target ``j`` of the scene is
    then a streak of drift ``D_j - D_i`` (``D = (-k lambda PRF / 2, 2 v)``) centred on its own
    look position. The sum of their amplitudes ``sqrt(I_j level / I_i)`` is returned.

    Args:
        position: ``(B, N, 2)`` image positions (m).
        speed: ``(B, N)`` along-track speeds (m/s).
        fold: long ``(B, N)`` folds.
        intensity: ``(B, N)`` focused peak intensities.
        valid: bool ``(B, N)``.
        plan: the looks.
        params: the system.
        window: the image-formation taper.

    Returns:
        float64 ``(B, N, K)``.
    """
    pos = torch.nan_to_num(position.double())
    v, k = speed.double().nan_to_num(), fold.long()
    rates = torch.stack([-k.double() * params.geometry.blind_speed, 2 * v], -1)
    drift = rates[:, None, :, :] - rates[:, :, None, :]  # (B, i, j, 2)
    period = torch.tensor(
        [params.geometry.unambiguous_range, params.geometry.unambiguous_azimuth],
        dtype=torch.float64,
    )
    aperture = float(plan.stop[0] - plan.start[0]) / params.track.prf
    amp = intensity.double().nan_to_num().clamp(min=0).sqrt()
    others = valid[:, None, :] & valid[:, :, None] & ~torch.eye(valid.shape[1], dtype=torch.bool)
    out = []
    for t in plan.time.tolist():
        at = _look_positions(pos, v, k, t, params)
        delta = at[:, :, None] - at[:, None, :]
        delta = delta - period * torch.floor(delta / period + 0.5)
        level = streak_level(delta, drift, params, aperture=aperture, window=window)
        ratio = amp[:, None, :] * level.sqrt() / amp[:, :, None].clamp(min=1e-300)
        out.append(torch.where(others, ratio, 0.0).sum(-1))
    return torch.stack(out, -1)
