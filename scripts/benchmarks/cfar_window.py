"""Benchmark cases: window-based CFAR against scipy.ndimage references of the same statistic,
and the cost of summing every window cell by cell (the CPU's sums of rectangles and rings,
as a GPU adds them: nothing cancels) against the integral images they replaced."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from scipy import ndimage

import torchsar as ts
from torchsar import windows

GUARD, TRAIN = 2, 4


def _scipy_ring_moments(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ring mean and second moment with scipy.ndimage.uniform_filter (outer box - guard box)."""
    o, i = 2 * (GUARD + TRAIN) + 1, 2 * GUARD + 1
    n = o * o - i * i
    mo = ndimage.uniform_filter(a, o, mode="constant")
    mi = ndimage.uniform_filter(a, i, mode="constant")
    a2 = a * a
    qo = ndimage.uniform_filter(a2, o, mode="constant")
    qi = ndimage.uniform_filter(a2, i, mode="constant")
    return (mo * o * o - mi * i * i) / n, (qo * o * o - qi * i * i) / n


def scipy_two_parameter(a: np.ndarray) -> np.ndarray:
    mu, m2 = _scipy_ring_moments(a)
    return (a - mu) / np.sqrt(np.maximum(m2 - mu * mu, 0))


def scipy_ca(a: np.ndarray) -> np.ndarray:
    o, i = 2 * (GUARD + TRAIN) + 1, 2 * GUARD + 1
    mo = ndimage.uniform_filter(a, o, mode="constant")
    mi = ndimage.uniform_filter(a, i, mode="constant")
    return a / ((mo * o * o - mi * i * i) / (o * o - i * i))


def _ring_sums(x: torch.Tensor, valid: torch.Tensor | None, direct: bool) -> object:
    """The strip sums of the default ring (two moments) over ``x``, cell by cell
    (``direct``) or by integral images of ``x - mean``."""
    chosen = windows._direct
    if not direct:
        windows._direct = lambda *_: False
    try:
        ring = ts.windows.Ring(GUARD, TRAIN)
        return windows.windowed(x, [ring.region], lambda xs, s: s[0].s1, valid=valid)
    finally:
        windows._direct = chosen


def cases() -> list[tuple[str, Callable[[], object], Callable[[], object]]]:
    gen = torch.Generator().manual_seed(0)
    small = torch.empty(1, 1, 512, 512).exponential_(generator=gen)
    valid = torch.rand(small.shape, generator=gen) > 0.05
    x = torch.empty(1, 1, 1024, 1024).exponential_(generator=gen)
    a = x[0, 0].numpy()
    return [
        (
            "two_parameter 1024x1024 f32 (g=2,t=4) vs scipy uniform_filter",
            lambda: ts.cfar.two_parameter(x, guard=GUARD, train=TRAIN),
            lambda: scipy_two_parameter(a),
        ),
        (
            "ca 1024x1024 f32 (g=2,t=4) vs scipy uniform_filter",
            lambda: ts.cfar.ca(x, guard=GUARD, train=TRAIN),
            lambda: scipy_ca(a),
        ),
        (
            "go 1024x1024 f32 (g=2,t=4) vs scipy ca (uniform_filter; not like for like)",
            lambda: ts.cfar.go(x, guard=GUARD, train=TRAIN),
            lambda: scipy_ca(a),
        ),
        (
            "ring sums 512x512 f32 (g=2,t=4: 144 cells, 2 moments) cell by cell vs integral images",
            lambda: _ring_sums(small, None, True),
            lambda: _ring_sums(small, None, False),
        ),
        (
            "ring sums 512x512 f32 (g=2,t=4, no-data mask) cell by cell vs integral images",
            lambda: _ring_sums(small, valid, True),
            lambda: _ring_sums(small, valid, False),
        ),
    ]
