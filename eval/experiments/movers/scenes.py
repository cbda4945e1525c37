"""Scenes of the mover ladder: four point targets (one moving) in weak distributed clutter."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar.motion import SpotlightParams, polar_format
from torchsar.sar import add_noise, simulate_phase_history

__all__ = ["LAYOUT", "MOVER", "Clutter", "make_clutter", "noise_std", "simulate_scenes"]

# (range, azimuth) m: three stationary targets and the right-most (largest azimuth) mover,
# at different ranges so no two share a range cell.
LAYOUT = ((-25.0, -20.0), (20.0, -8.0), (-5.0, 6.0), (10.0, 20.0))
MOVER = 3


def noise_std(params: SpotlightParams, snr_db: float) -> float:
    """Per-sample noise giving image peak SNR ``snr_db`` for a unit point (Hann in 2-D)."""
    m, k = params.geometry.pulses, params.geometry.samples
    gain = (0.5 * m * 0.5 * k) / math.sqrt(0.375 * m * 0.375 * k)  # sum w / sqrt(sum w^2)
    return gain * 10 ** (-snr_db / 20)


@dataclass(frozen=True)
class Clutter:
    """A pool of clutter phase histories ``(R, M, K)`` with unit mean image intensity."""

    phase_history: Tensor
    points: int

    def scaled(self, index: Tensor, power: float) -> Tensor:
        """Realisations ``index % R`` scaled to mean image intensity ``power``."""
        if self.points == 0:
            return torch.zeros(())
        return self.phase_history[index % self.phase_history.shape[0]] * math.sqrt(power)


def make_clutter(
    params: SpotlightParams, *, points: int, realisations: int, seed: int, size
) -> Clutter:
    """``realisations`` fields of ``points`` weak scatterers with complex Gaussian amplitudes.

    Scatterers are uniform over the imaged extent; each field is normalised so its
    full-aperture image has mean intensity 1 (measured on the formed image).
    """
    if points == 0:
        return Clutter(
            torch.zeros(0, params.geometry.pulses, params.geometry.samples, dtype=torch.complex64),
            0,
        )
    gen = torch.Generator().manual_seed(seed)
    ext = torch.tensor(params.image_extent, dtype=torch.float64)
    pos = (torch.rand(realisations, points, 2, generator=gen, dtype=torch.float64) - 0.5) * ext
    amp = torch.randn(realisations, points, generator=gen, dtype=torch.complex128)
    g = simulate_phase_history(pos, params.geometry, amplitudes=amp).to(torch.complex64)
    mean = polar_format(g, params, size=size).abs().square().mean(dim=(-2, -1))
    return Clutter(g / mean.sqrt()[:, None, None], points)


def simulate_scenes(
    params: SpotlightParams,
    velocities: Tensor,
    *,
    snr_db: Tensor,
    cnr_db: float,
    clutter: Clutter,
    seeds: Tensor,
    mover: bool = True,
) -> tuple[Tensor, Tensor]:
    """Phase histories ``(B, M, K)`` of the layout with the mover at ``velocities (B, 2)``.

    Per scene ``b``: noise from seed ``seeds[b]``, clutter realisation ``seeds[b]``
    scaled to ``cnr_db`` over the noise, image peak SNR ``snr_db[b]`` of every target.
    Without ``mover`` the moving target is left out (control scenes).

    Returns:
        ``(g, positions)``: complex64 ``(B, M, K)`` and float64 ``(B, N, 2)``.
    """
    b = velocities.shape[0]
    pos = torch.tensor(LAYOUT, dtype=torch.float64).expand(b, -1, -1).clone()
    vel = torch.zeros_like(pos)
    vel[:, MOVER] = velocities.to(torch.float64)
    if not mover:
        pos, vel = pos[:, :MOVER], vel[:, :MOVER]
    out = []
    for i in range(b):
        sigma = noise_std(params, float(snr_db[i]))
        g = simulate_phase_history(pos[i : i + 1], params.geometry, velocities=vel[i : i + 1])
        g = add_noise(g, std=sigma, seed=int(seeds[i])).to(torch.complex64)
        noise_power = 10 ** (-float(snr_db[i]) / 10)
        out.append(g + clutter.scaled(seeds[i : i + 1], noise_power * 10 ** (cnr_db / 10)))
    return torch.cat(out), pos
