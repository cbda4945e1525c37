"""Binary closing of stacked bool planes by a digital disk, extensive at the image border.

Two paths with the same result: the numba kernel (:mod:`torchsar.objects._kernels`, which
visits only the pixels near the set ones) when :func:`torchsar._jit.enabled`, else plain
NumPy on the whole planes (separable shifts; many small passes, which intra-op threading
only slows down).
"""

from __future__ import annotations

import math

import numpy as np

from torchsar import _jit

__all__ = ["close_mask", "close_pixels"]


def _disk_rectangles(radius: int) -> list[tuple[int, int]]:
    """Half-sizes ``(dy, dx)`` of rectangles whose union is the digital disk of ``radius``
    (pixels with ``dy^2 + dx^2 <= radius^2``)."""
    return [(dy, math.isqrt(radius * radius - dy * dy)) for dy in range(radius + 1)]


def _spread(x: np.ndarray, d: int, axis: int) -> np.ndarray:
    """OR of ``x`` shifted by ``-d..d`` along ``axis`` (values beyond the edge count as 0);
    ``x`` itself when ``d == 0``."""
    if d == 0:
        return x
    out = x.copy()
    n = x.shape[axis]
    for k in range(1, min(d, n - 1) + 1):
        lo = [slice(None)] * x.ndim
        hi = [slice(None)] * x.ndim
        lo[axis], hi[axis] = slice(0, n - k), slice(k, n)
        out[tuple(hi)] |= x[tuple(lo)]
        out[tuple(lo)] |= x[tuple(hi)]
    return out


def _dilate(x: np.ndarray, rects: list[tuple[int, int]]) -> np.ndarray:
    """Dilation of bool planes ``(N, H, W)`` by a union of rectangles ``(dy, dx)`` sorted by
    ``dy`` (separable shifts, the row spreads built on each other; outside the planes
    counts as unset)."""
    out, rows, at = None, x, 0
    for dy, dx in rects:
        rows, at = _spread(rows, dy - at, -2), dy
        part = _spread(rows, dx, -1)
        if out is None:
            out = part.copy() if part is x else part
        else:
            out |= part
    return np.zeros_like(x) if out is None else out


def close_mask(mask: np.ndarray, radius: int) -> np.ndarray:
    """Binary closing of bool planes ``(N, H, W)`` with a disk of ``radius``, extensive (never
    removes a pixel) also at the image border: dilation of the zero-padded mask, then
    erosion as the complement of the dilated complement (the outside counting as set).

    Examples:
        >>> m = np.zeros((1, 5, 5), bool); m[0, 1:4, 1] = m[0, 1:4, 3] = True
        >>> close_mask(m, 1)[0, 2].astype(int).tolist()
        [0, 1, 1, 1, 0]
    """
    if radius == 0 or not mask.any():
        return mask
    rects = _disk_rectangles(radius)
    x = np.pad(mask, ((0, 0), (radius, radius), (radius, radius)))
    closed = ~_dilate(~_dilate(x, rects), rects)
    return closed[:, radius:-radius, radius:-radius] | mask


def close_pixels(idx: np.ndarray, shape: tuple[int, int, int], radius: int) -> np.ndarray:
    """:func:`close_mask` of the stack ``shape`` ``(N, H, W)`` whose set pixels are ``idx``
    (flat indices, ascending): the set pixels of the closing, ascending.

    Examples:
        >>> close_pixels(np.array([6, 8, 11, 13, 16, 18]), (1, 5, 5), 1).tolist()
        [6, 8, 11, 12, 13, 16, 18]
    """
    if radius == 0 or idx.size == 0:
        return idx
    if _jit.enabled():
        from torchsar.objects import _kernels

        return _kernels.close_disk(idx, shape, radius)
    mask = np.zeros(int(np.prod(shape)), bool)
    mask[idx] = True
    return np.flatnonzero(close_mask(mask.reshape(shape), radius))
