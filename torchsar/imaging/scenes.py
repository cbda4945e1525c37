"""Complex reflectivity scenes for imaging experiments: sparse points, speckled extended scenes.

These are what a phase history is simulated *from* (:func:`torchsar.sar.phase_history`):
complex ``(B, 1, H, W)`` reflectivity on the polar-raster pixel grid. The detection datasets
of :mod:`torchsar.simulate` are a different product: intensity images with ground truth.
Scene ``b`` of a batch draws from its own generator seeded with
:func:`~torchsar.simulate.image_seed` ``(seed, b)``, so it does not depend on the batch size.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar._checks import check_device, check_int, check_positive
from torchsar.errors import OptionError
from torchsar.seeding import check_seed, image_seed, make_generator

__all__ = ["point_scene", "speckled_scene"]


def _dtype(dtype: torch.dtype) -> torch.dtype:
    if dtype not in (torch.complex64, torch.complex128):
        raise OptionError(f"dtype must be torch.complex64 or torch.complex128, got {dtype}")
    return dtype


def _generators(batch: int, seed: int) -> list[torch.Generator]:
    """One CPU generator per scene, seeded with ``image_seed(seed, b)``."""
    check_seed(seed)
    return [make_generator(image_seed(seed, b)) for b in range(batch)]


def point_scene(
    batch: int,
    *,
    size: tuple[int, int] = (64, 64),
    points: int = 20,
    margin: int = 0,
    seed: int = 0,
    dtype: torch.dtype = torch.complex64,
    device=None,
) -> tuple[Tensor, Tensor]:
    """Sparse scenes of point scatterers on distinct pixels.

    Amplitudes are uniform in ``[0.5, 1]`` with uniform random phase.

    Args:
        batch: number of scenes ``B``.
        size: ``(H, W)``.
        points: scatterers per scene.
        margin: keep scatterers this many pixels away from the border.
        seed: random seed, an int in ``[0, 2**63)``.
        dtype: complex64 or complex128.
        device: output device (an unavailable one raises :class:`OptionError`).

    Returns:
        ``(reflectivity, mask)``: complex ``(B, 1, H, W)`` and bool support ``(B, 1, H, W)``.

    Examples:
        >>> f, m = point_scene(2, size=(16, 16), points=5, seed=0)
        >>> f.shape, int(m.sum())
        (torch.Size([2, 1, 16, 16]), 10)
    """
    check_int(batch, "batch", minimum=0)
    device = check_device(device)
    h, w = size
    check_int(margin, "margin", minimum=0)
    inner = (h - 2 * margin) * (w - 2 * margin)
    check_int(points, "points", minimum=0)
    if points > inner:
        raise OptionError(f"points must be <= {inner} free pixels, got {points}")
    dtype = _dtype(dtype)
    real = torch.float64 if dtype == torch.complex128 else torch.float32
    f = torch.zeros(batch, h * w, dtype=dtype)
    for b, gen in enumerate(_generators(batch, seed)):
        keys = torch.rand(inner, generator=gen, dtype=real).argsort()[:points]
        rows = keys // (w - 2 * margin) + margin
        cols = keys % (w - 2 * margin) + margin
        amp = 0.5 + 0.5 * torch.rand(points, generator=gen, dtype=real)
        phase = (2 * torch.rand(points, generator=gen, dtype=real) - 1) * math.pi
        f[b, rows * w + cols] = torch.polar(amp, phase).to(dtype)
    f = f.reshape(batch, 1, h, w).to(device)
    return f, f != 0


def speckled_scene(
    batch: int,
    *,
    size: tuple[int, int] = (64, 64),
    targets: int = 3,
    target_size: tuple[int, int] = (3, 6),
    contrast: float = 20.0,
    seed: int = 0,
    dtype: torch.dtype = torch.complex64,
    device=None,
) -> tuple[Tensor, Tensor]:
    """Extended scenes: rectangles ``contrast`` times brighter than clutter, fully speckled.

    The mean intensity is 1 on clutter and ``contrast`` on targets; the reflectivity is
    circular complex Gaussian with that variance (single-look speckle).

    Args:
        batch: number of scenes.
        size: ``(H, W)``.
        targets: rectangles per scene.
        target_size: ``(min, max)`` side length in pixels.
        contrast: target-to-clutter mean intensity ratio.
        seed: random seed, an int in ``[0, 2**63)``.
        dtype: complex64 or complex128.
        device: output device (an unavailable one raises :class:`OptionError`).

    Returns:
        ``(reflectivity, mask)``: complex ``(B, 1, H, W)`` and bool target mask ``(B, 1, H, W)``.

    Examples:
        >>> f, m = speckled_scene(1, size=(32, 32), seed=0)
        >>> f.shape, bool(m.any())
        (torch.Size([1, 1, 32, 32]), True)
    """
    check_int(batch, "batch", minimum=0)
    device = check_device(device)
    check_positive(contrast, "contrast")
    dtype = _dtype(dtype)
    real = torch.float64 if dtype == torch.complex128 else torch.float32
    h, w = size
    lo, hi = target_size
    mask = torch.zeros(batch, 1, h, w, dtype=torch.bool)
    f = torch.zeros(batch, 1, h, w, dtype=dtype)
    for b, gen in enumerate(_generators(batch, seed)):
        for _ in range(targets):
            th, tw = (int(v) for v in torch.randint(lo, hi + 1, (2,), generator=gen))
            r = int(torch.randint(0, max(1, h - th), (1,), generator=gen))
            c = int(torch.randint(0, max(1, w - tw), (1,), generator=gen))
            mask[b, 0, r : r + th, c : c + tw] = True
        mean = torch.where(mask[b, 0], torch.tensor(contrast, dtype=real), 1.0)
        re = torch.randn((h, w), generator=gen, dtype=real)
        im = torch.randn((h, w), generator=gen, dtype=real)
        f[b, 0] = ((mean / 2).sqrt() * torch.complex(re, im)).to(dtype)
    return f.to(device), mask.to(device)
