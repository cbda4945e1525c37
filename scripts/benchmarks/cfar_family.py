"""Benchmark cases for the CFAR family against scipy.ndimage references of the same statistic.

- ``os``: the exact ring order statistic (``torchsar.order_statistics.ring_order_statistic``)
  and the whole OS-CFAR vs ``scipy.ndimage.rank_filter`` with the same ring footprint (equal
  on every interior pixel; checked here before timing).
- ``ca``: CA-CFAR vs two ``uniform_filter`` box means (outer minus guard box).

Run on its own (``python scripts/benchmarks/cfar_family.py``) or through
``scripts/benchmark.py`` (1 thread, best of several runs, ratio = reference / ours).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import torchsar as ts
from torchsar.order_statistics import ring_order_statistic
from torchsar.windows import Ring

GUARD, TRAIN = 2, 4


def ring_footprint(guard: int, train: int) -> np.ndarray:
    o = guard + train
    fp = np.ones((2 * o + 1, 2 * o + 1), bool)
    fp[train : train + 2 * guard + 1, train : train + 2 * guard + 1] = False
    return fp


def scipy_os(a: np.ndarray, rank: int) -> np.ndarray:
    """OS-CFAR statistic with scipy: ``I / rank_filter`` (0-based rank ``rank - 1``)."""
    return a / ndimage.rank_filter(a, rank - 1, footprint=ring_footprint(GUARD, TRAIN))


def scipy_ca(a: np.ndarray) -> np.ndarray:
    o, i = 2 * (GUARD + TRAIN) + 1, 2 * GUARD + 1
    mo = ndimage.uniform_filter(a, o, mode="constant")
    mi = ndimage.uniform_filter(a, i, mode="constant")
    return a / ((mo * o * o - mi * i * i) / (o * o - i * i))


def _image(size: int) -> torch.Tensor:
    return torch.empty(1, 1, size, size).exponential_(generator=torch.Generator().manual_seed(0))


def _check_os_exact(x: torch.Tensor, rank: int) -> None:
    """The benchmark is only meaningful if both compute the same thing: assert equality."""
    ring, o = Ring(GUARD, TRAIN), GUARD + TRAIN
    ours = ring_order_statistic(x, ring, torch.full(x.shape, rank))[0, 0].numpy()
    ref = ndimage.rank_filter(x[0, 0].numpy(), rank - 1, footprint=ring_footprint(GUARD, TRAIN))
    if not np.array_equal(ours[o:-o, o:-o], ref[o:-o, o:-o]):
        raise AssertionError("ring_order_statistic differs from scipy.ndimage.rank_filter")


def cases() -> list[tuple[str, Callable[[], object], Callable[[], object]]]:
    x512, x1024 = _image(512), _image(1024)
    ring = Ring(GUARD, TRAIN)
    rank = round(3 * ring.n / 4)
    _check_os_exact(x512, rank)
    k512 = torch.full(x512.shape, rank)
    a512, a1024 = x512[0, 0].numpy(), x1024[0, 0].numpy()
    fp = ring_footprint(GUARD, TRAIN)
    return [
        (
            "os ring order statistic 512x512 (g=2,t=4,r=108) vs scipy rank_filter",
            lambda: ring_order_statistic(x512, ring, k512),
            lambda: ndimage.rank_filter(a512, rank - 1, footprint=fp),
        ),
        (
            "os cfar 512x512 f32 (g=2,t=4) vs scipy rank_filter statistic",
            lambda: ts.cfar.os(x512, guard=GUARD, train=TRAIN),
            lambda: scipy_os(a512, rank),
        ),
        (
            "ca cfar 1024x1024 f32 (g=2,t=4) vs scipy uniform_filter",
            lambda: ts.cfar.ca(x1024, guard=GUARD, train=TRAIN),
            lambda: scipy_ca(a1024),
        ),
        (
            "go cfar 1024x1024 f32 (g=2,t=4) vs scipy ca (uniform_filter)",
            lambda: ts.cfar.go(x1024, guard=GUARD, train=TRAIN),
            lambda: scipy_ca(a1024),
        ),
    ]


def _best(fn: Callable[[], object], repeat: int = 5) -> float:
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


if __name__ == "__main__":
    torch.set_num_threads(1)
    for name, ours, ref in cases():
        t_o, t_r = _best(ours), _best(ref)
        ms = f"ours {t_o * 1e3:8.1f} ms  ref {t_r * 1e3:8.1f} ms"
        print(f"{name:<72s} {ms}  ratio {t_r / t_o:5.2f}x")
