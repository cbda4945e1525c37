"""Benchmark cases for the CFAR family against scipy.ndimage references of the same statistic.

- ``os``: the exact ring order statistic (``torchsar.order_statistics.ring_order_statistic``)
  and the whole OS-CFAR vs ``scipy.ndimage.rank_filter`` with the same ring footprint (equal
  on every interior pixel; checked here before timing), on 512x512 with the default ring
  (g=2, t=4, N=144) and a wide one (g=4, t=8: 25^2 - 9^2 = 544 cells; target >= 8x).
- ``os ... torch path``: OS-CFAR with the compiled order statistic (numba, the default on
  CPU) vs the torch bisection / histogram it replaces (same output bit for bit), on 16
  simulated 128x128 chips (divide by 16 for ms/chip; target <= 3 ms/chip), with CA-CFAR on
  the same chips as a box-filter yardstick.
- ``os cost curve``: the ring order statistic on 256x256 for ``train`` = 4, 10, 15, 20, 25,
  40 (g=2): its cost must grow with the ring side, not with the ring area (the reference's
  does), so the ratio grows with ``train``. Run just the curve with ``--only "os curve"``.

CA, two-parameter and GO against ``uniform_filter`` references are in ``cfar_window.py``.
Run with ``python scripts/benchmark.py --topic cfar_family``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np
import torch
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import torchsar as ts
from torchsar import _jit
from torchsar.order_statistics import ring_order_statistic
from torchsar.windows import Ring


def torch_path(fn: Callable[[], object]) -> Callable[[], object]:
    """``fn`` run with the compiled kernels switched off (the torch algorithms)."""

    def run() -> object:
        old, _jit.ENABLED = _jit.ENABLED, False
        try:
            return fn()
        finally:
            _jit.ENABLED = old

    return run


GUARD, TRAIN = 2, 4


def ring_footprint(guard: int, train: int) -> np.ndarray:
    o = guard + train
    fp = np.ones((2 * o + 1, 2 * o + 1), bool)
    fp[train : train + 2 * guard + 1, train : train + 2 * guard + 1] = False
    return fp


def scipy_os(a: np.ndarray, rank: int) -> np.ndarray:
    """OS-CFAR statistic with scipy: ``I / rank_filter`` (0-based rank ``rank - 1``)."""
    return a / ndimage.rank_filter(a, rank - 1, footprint=ring_footprint(GUARD, TRAIN))


def _image(size: int) -> torch.Tensor:
    return torch.empty(1, 1, size, size).exponential_(generator=torch.Generator().manual_seed(0))


def _check_os_exact(x: torch.Tensor, rank: int, train: int = TRAIN, guard: int = GUARD) -> None:
    """The benchmark is only meaningful if both compute the same thing: assert equality."""
    ring, o = Ring(guard, train), guard + train
    ours = ring_order_statistic(x, ring, torch.full(x.shape, rank))[0, 0].numpy()
    ref = ndimage.rank_filter(x[0, 0].numpy(), rank - 1, footprint=ring_footprint(guard, train))
    if not np.array_equal(ours[o:-o, o:-o], ref[o:-o, o:-o]):
        raise AssertionError("ring_order_statistic differs from scipy.ndimage.rank_filter")


def curve_cases() -> list[tuple[str, Callable[[], object], Callable[[], object]]]:
    """The OS cost curve: one case per training-band width on a 256x256 image."""
    x = _image(256)
    a = x[0, 0].numpy()
    out = []
    for train in (4, 10, 15, 20, 25, 40):
        ring = Ring(GUARD, train)
        rank = round(3 * ring.n / 4)
        _check_os_exact(x, rank, train)
        k, fp = torch.full(x.shape, rank), ring_footprint(GUARD, train)
        out.append(
            (
                f"os curve 256x256 (g={GUARD},t={train},N={ring.n}) vs scipy rank_filter",
                partial(ring_order_statistic, x, ring, k),
                partial(ndimage.rank_filter, a, rank - 1, footprint=fp),
            )
        )
    return out


def cases() -> list[tuple[str, Callable[[], object], Callable[[], object]]]:
    x512 = _image(512)
    ring = Ring(GUARD, TRAIN)
    rank = round(3 * ring.n / 4)
    _check_os_exact(x512, rank)
    k512 = torch.full(x512.shape, rank)
    a512 = x512[0, 0].numpy()
    fp = ring_footprint(GUARD, TRAIN)
    wide = Ring(4, 8)
    wide_rank = round(3 * wide.n / 4)
    _check_os_exact(x512, wide_rank, train=8, guard=4)
    chips = ts.simulate.chips(16, seed=0).image
    return [
        *curve_cases(),
        (
            "os ring order statistic 512x512 (g=2,t=4,r=108) vs scipy rank_filter",
            lambda: ring_order_statistic(x512, ring, k512),
            lambda: ndimage.rank_filter(a512, rank - 1, footprint=fp),
        ),
        (
            f"os ring order statistic 512x512 (g=4,t=8,N={wide.n}) vs scipy rank_filter",
            partial(ring_order_statistic, x512, wide, torch.full(x512.shape, wide_rank)),
            partial(ndimage.rank_filter, a512, wide_rank - 1, footprint=ring_footprint(4, 8)),
        ),
        (
            "os cfar 512x512 f32 (g=2,t=4) vs scipy rank_filter statistic",
            lambda: ts.cfar.os(x512, guard=GUARD, train=TRAIN),
            lambda: scipy_os(a512, rank),
        ),
        (
            "os cfar 16 chips 128x128 (g=2,t=4) vs torch path",
            lambda: ts.cfar.os(chips, guard=GUARD, train=TRAIN),
            torch_path(lambda: ts.cfar.os(chips, guard=GUARD, train=TRAIN)),
        ),
        (
            "os cfar 16 chips 128x128 (g=2,t=4) vs ca cfar (box-filter yardstick)",
            lambda: ts.cfar.os(chips, guard=GUARD, train=TRAIN),
            lambda: ts.cfar.ca(chips, guard=GUARD, train=TRAIN),
        ),
    ]
