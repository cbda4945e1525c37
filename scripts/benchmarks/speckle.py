"""Benchmark cases: speckle filters against a scipy.ndimage.uniform_filter Lee filter.

Every torchsar filter (1024x1024 float32, 7x7 window) is timed against the same reference,
a straightforward Lee filter built from two ``uniform_filter`` calls, so the printed ratio
(reference / ours) reads as "speed relative to a box-filter Lee". Targets (issue 3): ``lee``
at most 1.5x the reference time (ratio >= 0.67), ``enhanced_frost`` at most 10x (>= 0.1).

Run: ``python scripts/benchmark.py --topic speckle``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from scipy import ndimage

import torchsar as ts

WINDOW, LOOKS = 7, 1.0


def scipy_lee(a: np.ndarray, window: int = WINDOW, looks: float = LOOKS) -> np.ndarray:
    """Lee filter from box means (reflect borders): ``mu + W (I - mu)``."""
    mu = ndimage.uniform_filter(a, window, mode="reflect")
    m2 = ndimage.uniform_filter(a * a, window, mode="reflect")
    ci2 = np.maximum(m2 - mu * mu, 0) / np.maximum(mu * mu, np.finfo(a.dtype).tiny)
    w = np.clip(1 - (1 / looks) / np.maximum(ci2, np.finfo(a.dtype).tiny), 0, 1)
    return mu + w * (a - mu)


def cases() -> list[tuple[str, Callable[[], object], Callable[[], object]]]:
    gen = torch.Generator().manual_seed(0)
    x = torch.empty(1, 1, 1024, 1024).exponential_(generator=gen)
    a = x[0, 0].numpy()
    out = []
    for name, fn in ts.speckle.FILTERS.items():
        out.append(
            (
                f"speckle.{name} 1024x1024 f32 w={WINDOW} vs scipy uniform_filter Lee",
                lambda fn=fn: fn(x, window=WINDOW, looks=LOOKS),
                lambda: scipy_lee(a),
            )
        )
    return out
