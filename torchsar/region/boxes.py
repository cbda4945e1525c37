"""Bounding boxes of pixel sets, widened by a margin and clipped to the image: the crops the
region CFAR works on instead of whole images."""

from __future__ import annotations

import numpy as np

__all__ = ["index_box", "mask_box"]

Box = tuple[int, int, int, int]  # r0, r1, c0, c1: end-exclusive


def _widen(
    rows: tuple[int, int], cols: tuple[int, int], shape: tuple[int, int], margin: int
) -> Box:
    """Rows ``rows[0]..rows[1]`` and columns ``cols[0]..cols[1]`` (inclusive) widened by
    ``margin`` on every side, clipped to ``shape``."""
    h, w = shape
    return (
        max(rows[0] - margin, 0),
        min(rows[1] + margin + 1, h),
        max(cols[0] - margin, 0),
        min(cols[1] + margin + 1, w),
    )


def index_box(idx: np.ndarray, shape: tuple[int, int], margin: int) -> Box:
    """The box of non-empty flat (row-major) indices ``idx`` of an image of ``shape``.

    Examples:
        >>> index_box(np.array([5, 6]), (4, 4), 1)
        (0, 3, 0, 4)
    """
    w = shape[1]
    lo, hi = np.minimum.reduce, np.maximum.reduce  # ufunc reductions: no wrapper overhead
    cols = idx % w
    return _widen(
        (int(lo(idx)) // w, int(hi(idx)) // w), (int(lo(cols)), int(hi(cols))), shape, margin
    )


def mask_box(mask: np.ndarray, margin: int = 0) -> tuple[slice, slice] | None:
    """The box of the set pixels of a bool ``(H, W)`` mask, as slices; None when none is set.

    Examples:
        >>> m = np.zeros((5, 5), bool); m[2, 3] = True
        >>> mask_box(m, 1)
        (slice(1, 4, None), slice(2, 5, None))
    """
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(mask.any(axis=0))
    r0, r1, c0, c1 = _widen(
        (int(rows[0]), int(rows[-1])), (int(cols[0]), int(cols[-1])), mask.shape, margin
    )
    return slice(r0, r1), slice(c0, c1)
