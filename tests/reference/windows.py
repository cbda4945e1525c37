"""Slow, obvious references for window statistics: explicit loops over cells."""

from __future__ import annotations

import math

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


def window_cells(x: np.ndarray, p: int, i: int, j: int, rects, ok: np.ndarray) -> list[float]:
    """The in-image cells of plane ``p`` of ``x`` ``(P, H, W)`` where ``ok``, in ``rects``
    (rows ``(r0, r1, c0, c1)`` of offsets, inclusive) around pixel ``(i, j)``, rectangle
    by rectangle and each row by row (the direct-sum kernels' order), as floats."""
    h, w = x.shape[-2:]
    return [
        float(x[p, i + a, j + b])
        for r0, r1, c0, c1 in rects
        for a in range(r0, r1 + 1)
        for b in range(c0, c1 + 1)
        if 0 <= i + a < h and 0 <= j + b < w and ok[p, i + a, j + b]
    ]


def first_cells(x: np.ndarray, parts, valid: np.ndarray | None = None) -> np.ndarray:
    """The value of the first in-image (and ``valid``) cell of the rectangles of ``parts``
    (every region's in order, each row by row) around every pixel of ``x`` ``(P, H, W)``:
    the kernel's shift (0 where none is)."""
    ok = np.ones(x.shape, bool) if valid is None else valid
    rects = [rect for part in parts for rect in part]
    out = np.zeros(x.shape)
    for p, i, j in np.ndindex(*x.shape):
        cells = window_cells(x, p, i, j, rects, ok)
        out[p, i, j] = cells[0] if cells else 0.0
    return out


def exact_sums(x: np.ndarray, rects, shift: np.ndarray, valid: np.ndarray | None = None):
    """``sum(x - shift)``, ``sum((x - shift)^2)`` and the count over the in-image (and
    ``valid``) cells of the union of ``rects`` around every pixel of ``x`` ``(P, H, W)``
    (``shift``: per pixel), summed exactly (``math.fsum``)."""
    ok = np.ones(x.shape, bool) if valid is None else valid
    s1, s2, n = np.zeros(x.shape), np.zeros(x.shape), np.zeros(x.shape)
    for p, i, j in np.ndindex(*x.shape):
        d = [v - shift[p, i, j] for v in window_cells(x, p, i, j, rects, ok)]
        s1[p, i, j] = math.fsum(d)
        s2[p, i, j] = math.fsum(v * v for v in d)
        n[p, i, j] = len(d)
    return s1, s2, n


def ordered_sums(x: np.ndarray, rects, shift: np.ndarray, valid: np.ndarray | None = None):
    """:func:`exact_sums` added one cell after the other in float64, rectangle by rectangle,
    each row by row (the direct-sum kernels' order, so their values bit for bit)."""
    ok = np.ones(x.shape, bool) if valid is None else valid
    s1, s2, n = np.zeros(x.shape), np.zeros(x.shape), np.zeros(x.shape)
    for p, i, j in np.ndindex(*x.shape):
        t1 = t2 = 0.0
        cells = window_cells(x, p, i, j, rects, ok)
        for v in cells:
            d = v - float(shift[p, i, j])
            t1 += d
            t2 += d * d
        s1[p, i, j], s2[p, i, j], n[p, i, j] = t1, t2, len(cells)
    return s1, s2, n
