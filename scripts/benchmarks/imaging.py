"""Benchmark cases for torchsar.imaging: batched autofocus against per-scene calls.

The acceptance criterion of the batched solver: ``B`` scenes in one call are no slower than
``B`` separate calls (items stop individually, so batching costs no extra iterations).
Run: ``python scripts/benchmark.py --topic imaging``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

import torchsar.imaging as ti
import torchsar.sar as sar


def _data(batch: int, size: int, error: str, seed: int = 0) -> torch.Tensor:
    f, _ = ti.point_scene(batch, size=(size, size), points=round(0.02 * size * size), seed=seed)
    geometry = sar.SpotlightGeometry.for_image((size, size))
    g = sar.add_noise(sar.phase_history(f, geometry), snr_db=30.0, seed=seed)
    error_seed = seed + 1  # phase errors independent of the scenes and the noise
    if error == "1d":
        phi = ti.uniform_phase_error(batch, size, amplitude=math.pi, seed=error_seed)
    else:
        phi = ti.uniform_phase_error(batch, size, size, amplitude=0.75 * math.pi, seed=error_seed)
    return ti.apply_phase_error(g, phi)


def _batched_vs_loop(name: str, g: torch.Tensor, error: str) -> tuple[str, Callable, Callable]:
    def ours() -> object:
        return ti.sparse_autofocus(g, error=error)

    def loop() -> object:
        return [ti.sparse_autofocus(g[i : i + 1], error=error) for i in range(g.shape[0])]

    return (name, ours, loop)


def cases() -> list[tuple[str, Callable[[], object], Callable[[], object]]]:
    g64 = _data(32, 64, "1d")
    g64_2d = _data(32, 64, "2d", seed=1)
    g128 = _data(8, 128, "1d", seed=2)
    img = ti.ifft2c(g64).unsqueeze(1)
    return [
        _batched_vs_loop("sparse_autofocus 1d 32x(64x64) one call vs 32 calls", g64, "1d"),
        _batched_vs_loop("sparse_autofocus 2d 32x(64x64) one call vs 32 calls", g64_2d, "2d"),
        _batched_vs_loop("sparse_autofocus 1d 8x(128x128) one call vs 8 calls", g128, "1d"),
        (
            "pga 32x(64x64) one call vs 32 calls",
            lambda: ti.pga(img),
            lambda: [ti.pga(img[i : i + 1]) for i in range(32)],
        ),
    ]
