"""Slow, obvious references for window statistics: explicit loops over cells."""

from __future__ import annotations

import numpy as np


def ring_cells(
    img: np.ndarray, i: int, j: int, guard: int, train: int, valid: np.ndarray | None = None
) -> np.ndarray:
    """Values of the in-image (and valid) ring cells around (i, j)."""
    h, w = img.shape
    o = guard + train
    out = []
    for di in range(-o, o + 1):
        for dj in range(-o, o + 1):
            if max(abs(di), abs(dj)) <= guard:
                continue
            r, c = i + di, j + dj
            if 0 <= r < h and 0 <= c < w and (valid is None or valid[r, c]):
                out.append(img[r, c])
    return np.asarray(out, dtype=np.float64)


def rect_cells(img: np.ndarray, i: int, j: int, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
    """Values of the in-image cells at offsets [r0, r1] x [c0, c1] from (i, j)."""
    h, w = img.shape
    return np.asarray(
        [
            img[i + a, j + b]
            for a in range(r0, r1 + 1)
            for b in range(c0, c1 + 1)
            if 0 <= i + a < h and 0 <= j + b < w
        ],
        dtype=np.float64,
    )


def interior(h: int, w: int, radius: int) -> tuple[slice, slice]:
    """Slices of the pixels whose full window lies inside the image."""
    return slice(radius, h - radius), slice(radius, w - radius)
