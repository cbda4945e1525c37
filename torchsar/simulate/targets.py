"""Target models: vehicle-like and building-like reflectivity on a rotated rectangle.

Levels are in dB over the local clutter mean and always inside ``db = (lo, hi)``:

- vehicle: a body return ``lo + U(1, 0.3 (hi - lo))`` dB with +-2 dB facet fluctuation, plus
  3–7 dominant point scatterers (Gaussian blobs, sigma 0.7–1.3 px) peaking at
  ``U(lo + 0.6 (hi - lo), hi)`` dB, so the mask is an extended object with a few bright peaks.
- building: a dim roof ``U(lo, lo + 0.2 (hi - lo))`` dB, a 2-px bright rim (wall/ground
  double bounce) at ``U(lo + 0.4 (hi - lo), lo + 0.7 (hi - lo))`` dB, the brightest corners
  (4 px) at ``U(hi - 3, hi)`` dB and 2–6 roof scatterers.

The value inside the body is finally clamped to ``[lo, hi]`` dB.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar.seeding import Draws
from torchsar.simulate.canvas import Placed
from torchsar.simulate.shapes import Box, RotatedRect

__all__ = ["Raster", "building_levels", "place", "random_heading", "rasterise", "vehicle_levels"]


@dataclass(frozen=True)
class Raster:
    """A rectangle rasterised in its bounding ``box``: local coordinates and body mask."""

    box: Box
    u: Tensor
    v: Tensor
    body: Tensor


def rasterise(rect: RotatedRect, size: tuple[int, int], device: torch.device) -> Raster:
    """Rasterise ``rect`` on an image of ``size = (H, W)`` (clipped to the image)."""
    box = rect.box(*size)
    u, v = rect.local(box, device)
    return Raster(box, u, v, rect.covers(u, v))


def _facets(shape: tuple[int, int], spread_db: float, draws: Draws) -> Tensor:
    """Per-pixel facet fluctuation uniform in ``[-spread_db, spread_db]`` dB."""
    gen = draws.generator
    u = torch.rand(shape, generator=gen, device=gen.device, dtype=torch.float32)
    return (2.0 * u - 1.0) * spread_db


def _scatterers(rect: RotatedRect, u: Tensor, v: Tensor, k: int, peak_db, draws: Draws) -> Tensor:
    """Level in dB of the brightest of ``k`` Gaussian point scatterers inside ``rect``.

    A scatterer of peak ``p`` dB and width ``sigma`` contributes
    ``p - 10 log10(e) d^2 / (2 sigma^2)`` dB at distance ``d`` (a Gaussian blob in intensity);
    the maximum is taken in dB, which avoids one ``exp`` per scatterer and pixel.
    """
    us = torch.tensor(draws.uniform(-0.45 * rect.length, 0.45 * rect.length, k), device=u.device)
    vs = torch.tensor(draws.uniform(-0.4 * rect.width, 0.4 * rect.width, k), device=u.device)
    peaks = torch.tensor(draws.uniform(peak_db[0], peak_db[1], k), device=u.device)
    sigma = torch.tensor(draws.uniform(0.7, 1.3, k), device=u.device)
    d2 = (u[None] - us[:, None, None].float()) ** 2 + (v[None] - vs[:, None, None].float()) ** 2
    scale = (10.0 / math.log(10.0)) / (2.0 * sigma.float()[:, None, None] ** 2)
    return (peaks.float()[:, None, None] - scale * d2).amax(dim=0)


def _combine(base_db: Tensor, peaks_db: Tensor, db: tuple[float, float]) -> Tensor:
    """Brighter of two dB maps, clamped to ``db``."""
    return torch.clamp(torch.maximum(base_db, peaks_db), db[0], db[1])


def vehicle_levels(rect: RotatedRect, u: Tensor, v: Tensor, db, draws: Draws) -> Tensor:
    """Vehicle reflectivity in dB over clutter at local coordinates ``(u, v)``."""
    lo, hi = db
    base = draws.uniform(lo + 1.0, lo + max(1.0, 0.3 * (hi - lo)))
    body = base + _facets(tuple(u.shape), 2.0, draws)
    k = draws.integer(3, 7)
    peaks = _scatterers(rect, u, v, k, (lo + 0.6 * (hi - lo), hi), draws)
    return _combine(body, peaks, db)


def building_levels(rect: RotatedRect, u: Tensor, v: Tensor, db, draws: Draws) -> Tensor:
    """Building reflectivity in dB: dim roof, bright rim, brightest corners, roof scatterers."""
    lo, hi = db
    roof = draws.uniform(lo, lo + 0.2 * (hi - lo))
    rim = draws.uniform(lo + 0.4 * (hi - lo), lo + 0.7 * (hi - lo))
    corner = draws.uniform(hi - 3.0, hi)
    du, dv = 0.5 * rect.length - u.abs(), 0.5 * rect.width - v.abs()
    level = torch.full(tuple(u.shape), roof, device=u.device)
    level = torch.where((du < 2.0) | (dv < 2.0), rim, level)
    level = torch.where((du < 4.0) & (dv < 4.0), corner, level)
    level = level + _facets(tuple(u.shape), 1.5, draws)
    peaks = _scatterers(rect, u, v, draws.integer(2, 6), (lo + 0.3 * (hi - lo), rim), draws)
    return _combine(level, peaks, db)


_LEVELS = {"vehicle": vehicle_levels, "building": building_levels}


def place(
    kind: str,
    rect: RotatedRect,
    raster: Raster,
    *,
    db: tuple[float, float],
    clutter_mean: float,
    shadow_px: int,
    shadow_gain: float,
    draws: Draws,
) -> Placed:
    """Draw the levels of a rasterised target: a :class:`Placed` target ready to paint."""
    level_db = _LEVELS[kind](rect, raster.u, raster.v, db, draws)
    return Placed(
        kind, rect, raster.box, raster.body, level_db, clutter_mean, shadow_px, shadow_gain
    )


def random_heading(draws: Draws) -> float:
    """A heading uniform in ``[0, pi)`` radians."""
    return draws.uniform(0.0, math.pi)
