"""Slow/fast-time sampling grids and slant-range histories of the spotlight geometry.

The conventions are those of :mod:`torchsar.motion.params`: points ``(range, azimuth)`` in
metres relative to the scene centre, platform at ``(-R0, V t)``, ``t = 0`` mid-aperture.
All geometry is computed in float64 (slant ranges are ~1e4 m and the phase needs mm).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar.motion.params import SPEED_OF_LIGHT, SpotlightParams

__all__ = ["frequencies", "look_tangents", "pulse_times", "slant_ranges", "wavenumbers"]


def pulse_times(params: SpotlightParams, *, device: torch.device | str | None = None) -> Tensor:
    """Slow times ``t_m = (m - (M - 1) / 2) / PRF`` of the ``M`` pulses, float64 ``(M,)``."""
    m = torch.arange(params.n_pulses, dtype=torch.float64, device=device)
    return (m - (params.n_pulses - 1) / 2) / params.prf


def frequencies(params: SpotlightParams, *, device: torch.device | str | None = None) -> Tensor:
    """Instantaneous frequencies ``f_k = f0 + (k - (K - 1) / 2) gamma / fs`` in Hz, ``(K,)``."""
    k = torch.arange(params.n_samples, dtype=torch.float64, device=device)
    return params.center_frequency + (k - (params.n_samples - 1) / 2) * params.frequency_step


def wavenumbers(params: SpotlightParams, *, device: torch.device | str | None = None) -> Tensor:
    """Two-way wavenumbers ``kappa_k = 4 pi f_k / c`` in rad/m, ``(K,)``."""
    return 4 * math.pi * frequencies(params, device=device) / SPEED_OF_LIGHT


def slant_ranges(
    points: Tensor, params: SpotlightParams, times: Tensor, velocities: Tensor | None = None
) -> Tensor:
    """Slant range of each point at each slow time, float64 ``(..., M)``.

    A moving point is at ``points + velocities * t`` (constant velocity, positions updated
    per pulse).

    Args:
        points: ``(..., 2)`` positions ``(range, azimuth)`` at ``t = 0`` in m.
        params: the system.
        times: ``(M,)`` slow times in s.
        velocities: optional ``(..., 2)`` velocities ``(range, azimuth)`` in m/s.
    """
    p = points.to(torch.float64)
    t = times.to(torch.float64)
    rng = p[..., 0:1] + params.scene_range
    azi = p[..., 1:2] - params.platform_speed * t
    if velocities is not None:
        v = velocities.to(torch.float64)
        rng = rng + v[..., 0:1] * t
        azi = azi + v[..., 1:2] * t
    return torch.hypot(rng, azi)


def look_tangents(params: SpotlightParams, center: tuple[float, float], times: Tensor) -> Tensor:
    """``tan(theta_m)`` of the line of sight to ``center``: ``(x_c - V t) / (R0 + y_c)``, ``(M,)``.

    Exactly linear in slow time for a straight track, which lets the polar-format azimuth
    transform be one chirp-z transform per range-frequency row.
    """
    return (center[1] - params.platform_speed * times.to(torch.float64)) / (
        params.scene_range + center[0]
    )
