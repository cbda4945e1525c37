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


def first_cells(x: np.ndarray, parts, valid: np.ndarray | None = None) -> np.ndarray:
    """The value of the first in-image (and ``valid``) cell of the rectangles of ``parts``
    (every region's in order, each row by row) around every pixel of ``x`` ``(P, H, W)``:
    the kernel's shift (0 where none is)."""
    p_, h, w = x.shape
    ok = np.ones(x.shape, bool) if valid is None else valid
    out = np.zeros(x.shape)
    for p in range(p_):
        for i in range(h):
            for j in range(w):
                cells = [
                    x[p, i + a, j + b]
                    for rects in parts
                    for r0, r1, c0, c1 in rects
                    for a in range(r0, r1 + 1)
                    for b in range(c0, c1 + 1)
                    if 0 <= i + a < h and 0 <= j + b < w and ok[p, i + a, j + b]
                ]
                out[p, i, j] = cells[0] if cells else 0.0
    return out


def exact_sums(x: np.ndarray, rects, shift: np.ndarray, valid: np.ndarray | None = None):
    """``sum(x - shift)``, ``sum((x - shift)^2)`` and the count over the in-image (and
    ``valid``) cells of the union of ``rects`` around every pixel of ``x`` ``(P, H, W)``
    (``shift``: per pixel), summed exactly (``math.fsum``)."""
    p_, h, w = x.shape
    ok = np.ones(x.shape, bool) if valid is None else valid
    s1, s2, n = np.zeros(x.shape), np.zeros(x.shape), np.zeros(x.shape)
    for p in range(p_):
        for i in range(h):
            for j in range(w):
                d = [
                    float(x[p, i + a, j + b]) - shift[p, i, j]
                    for r0, r1, c0, c1 in rects
                    for a in range(r0, r1 + 1)
                    for b in range(c0, c1 + 1)
                    if 0 <= i + a < h and 0 <= j + b < w and ok[p, i + a, j + b]
                ]
                s1[p, i, j] = math.fsum(d)
                s2[p, i, j] = math.fsum(v * v for v in d)
                n[p, i, j] = len(d)
    return s1, s2, n


def ordered_sums(x: np.ndarray, rects, shift: np.ndarray, valid: np.ndarray | None = None):
    """:func:`exact_sums` added one cell after the other in float64, rectangle by rectangle,
    each row by row (the direct-sum kernels' order, so their values bit for bit)."""
    p_, h, w = x.shape
    ok = np.ones(x.shape, bool) if valid is None else valid
    s1, s2, n = np.zeros(x.shape), np.zeros(x.shape), np.zeros(x.shape)
    for p in range(p_):
        for i in range(h):
            for j in range(w):
                t1 = t2 = 0.0
                for r0, r1, c0, c1 in rects:
                    for a in range(r0, r1 + 1):
                        for b in range(c0, c1 + 1):
                            ii, jj = i + a, j + b
                            if 0 <= ii < h and 0 <= jj < w and ok[p, ii, jj]:
                                d = float(x[p, ii, jj]) - float(shift[p, i, j])
                                t1 += d
                                t2 += d * d
                                n[p, i, j] += 1
                s1[p, i, j], s2[p, i, j] = t1, t2
    return s1, s2, n
