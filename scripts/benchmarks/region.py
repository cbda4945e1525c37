"""Benchmark cases: region-growing CFAR on chips and on speckled scenes with extended targets.

``ours`` is :func:`torchsar.region.region_cfar` as shipped (default preset, enhanced Frost
included; with numba the per-seed loop is compiled, see :mod:`torchsar.region._kernels`).
References, each giving the same output bit for bit:

- ``python path``: the numpy/Python path the kernel replaces (heap, then an exact flood fill
  for large regions; what runs without numba), on 16 simulated 128x128 chips (divide the
  printed times by 16 for ms/chip) and on a 512x512 scene;
- ``pure heap``: the Python path with ``budget=None``, the literal priority-queue growth.

Targets: chips <= 4 ms per chip on one thread; 512x512 < 1.5 s and 1024x1024 with ~50
targets < 5 s (the printed ``ours`` times).
Run: ``python scripts/benchmark.py --topic region``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

import torchsar as ts
from torchsar import _jit
from torchsar.region import region_cfar


def python_path(fn: Callable[[], object]) -> Callable[[], object]:
    """``fn`` run with the compiled kernels switched off (the numpy/Python path)."""

    def run() -> object:
        old, _jit.ENABLED = _jit.ENABLED, False
        try:
            return fn()
        finally:
            _jit.ENABLED = old

    return run


def scene(size: int, n_targets: int, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """1-look speckle over a 6 dB clutter edge with rectangular targets of 30-120 px (bright
    bodies), every third one with a parallel twin 3-8 px away (a tight group).

    Returns the intensity ``(1, 1, size, size)`` float32 and the instance ids (int32).
    """
    rng = np.random.default_rng(seed)
    clean = np.ones((size, size))
    clean[:, size // 2 :] = 4.0
    inst = np.zeros((size, size), dtype=np.int32)
    yy, xx = np.mgrid[:size, :size]
    k = 0
    for i in range(n_targets):
        length, width, th = rng.uniform(30, 120), rng.uniform(10, 30), rng.uniform(0, np.pi)
        cy, cx = rng.uniform(70, size - 70, size=2)
        gain = rng.uniform(4, 12)
        shifts = [0.0] if i % 3 else [0.0, width + rng.uniform(3, 8)]
        for off in shifts:
            u = (yy - cy) * np.cos(th) + (xx - cx) * np.sin(th)
            v = -(yy - cy) * np.sin(th) + (xx - cx) * np.cos(th) - off
            body = (np.abs(u) < length / 2) & (np.abs(v) < width / 2) & (inst == 0)
            k += 1
            inst[body] = k
            clean[body] = clean[int(cy), int(cx)] * gain
    img = clean * rng.exponential(1.0, size=clean.shape)
    as_t = torch.from_numpy
    return as_t(img).float()[None, None], as_t(inst)[None, None]


def cases() -> list[tuple[str, Callable[[], object], Callable[[], object]]]:
    chips = ts.simulate.chips(16, seed=0).image
    x512, _ = scene(512, 12)
    out = [
        (
            "region_cfar 16 chips 128x128 (python path)",
            lambda: region_cfar(chips),
            python_path(lambda: region_cfar(chips)),
        ),
        (
            "region_cfar 512x512, 12 targets (python path)",
            lambda: region_cfar(x512),
            python_path(lambda: region_cfar(x512)),
        ),
    ]
    for size, n in ((512, 12), (1024, 50)):
        x, _ = scene(size, n)
        out.append(
            (
                f"region_cfar {size}x{size}, {n} targets (pure heap reference)",
                lambda x=x: region_cfar(x),
                python_path(lambda x=x: region_cfar(x, budget=None)),
            )
        )
    return out
