"""numba kernel of the pinwheel-block CFARs without no-data (GO, SO): from the image to the
statistic and the mask in one sweep over its rows, with no full-size temporaries.

The four blocks (top ``t x (2g+t+1)``, right, bottom, left, tiling the ring) are summed as
CA-CFAR's ring is (:mod:`torchsar._box_kernels`): each image row is converted once to
float64 and kept in a ring buffer with its power-of-two row blocks; per output row, the
top and bottom blocks' ``t`` rows and the side blocks' ``2g + t + 1`` rows are summed down
each column, then along the row (:mod:`torchsar._block_sums`): every addition of
non-negative terms in an order fixed by the pixel's position alone, so the block means are
exact to a few float64 roundings, where the integral images of
:func:`torchsar.windows.windowed` (the tensor code, and the path with no-data) cancel.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from torchsar._block_sums import JIT, axis_count, block_sums, level_up, levels_for, ring_row

__all__ = ["block_ratio"]


@njit(**JIT, inline="always")
def _levels(blocks, depth, n):
    """Levels ``1 .. depth - 1`` of the block sums of ``blocks[0]`` (``n`` long, padded)."""
    for k in range(1, depth):
        level_up(blocks[k - 1], blocks[k], 1 << (k - 1), n - (1 << k) + 1)


@njit(**JIT, inline="always")
def _better(est, total, count, is_max):
    """``est`` or the mean ``total / count`` of a block with cells, whichever is larger
    (``is_max``) or smaller."""
    if count <= 0:
        return est
    m = total / count
    return (m if m > est else est) if is_max else (m if m < est else est)


@njit(**JIT, inline="always")
def _extreme(s0, s1, s2, s3, n0, n1, n2, n3, is_max):
    """The largest (``is_max``) or smallest of the block means over the blocks with cells,
    as :func:`torchsar.cfar.blocks.extreme_mean`: GO's at least 0, SO's 0 where no block
    has cells."""
    est = -np.inf if is_max else np.inf
    est = _better(est, s0, n0, is_max)
    est = _better(est, s1, n1, is_max)
    est = _better(est, s2, n2, is_max)
    est = _better(est, s3, n3, is_max)
    if is_max:
        return est if est > 0.0 else 0.0
    return 0.0 if est == np.inf else est


@njit(**JIT)
def block_ratio(x, guard, train, is_max, row_state, col_state, scale, threshold, out, mask):
    """GO's (``is_max``) or SO's statistic ``x / extreme block mean`` of every plane of
    ``x`` ``(P, H, W)`` into ``out`` (its dtype) and the decision ``out > threshold[0]``
    (``threshold`` in ``out``'s dtype) into the bool ``mask``; cells outside the image are
    not counted; ``0 / 0 = 0``. A pixel's border factor is ``scale[row_state[i],
    col_state[j]]`` (1 inside; ``-inf`` marks a pixel whose blocks hold no cell: its
    statistic is ``-inf``).

    Returns how many values of ``x`` are not a finite number ``>= 0`` (the input check,
    made as the values are read; ``out`` and ``mask`` mean nothing unless 0)."""
    p_, h, w = x.shape
    g, t, o = guard, train, guard + train
    side = o + g + 1  # the side blocks' rows, the top and bottom blocks' columns
    size = 2 * o + 1
    depth = levels_for(side)
    rows = np.zeros((depth, size, w))
    ring = rows.reshape(depth * size, w)  # level k, row r in row k size + r % size
    padded = w + 2 * o  # o zero columns a side
    ldepth, sdepth = levels_for(side), levels_for(t)
    top, bottom = np.zeros((ldepth, padded)), np.zeros((ldepth, padded))
    right, left = np.zeros((sdepth, padded)), np.zeros((sdepth, padded))
    sums = np.zeros((4, w))
    cols = np.zeros((4, w))  # each block's in-image columns at each pixel
    for j in range(w):
        cols[0, j] = axis_count(j, w, -o, g)
        cols[1, j] = axis_count(j, w, g + 1, o)
        cols[2, j] = axis_count(j, w, -g, o)
        cols[3, j] = axis_count(j, w, -o, -g - 1)
    empty = x[0, 0] if p_ and h else np.zeros(w, x.dtype)  # a row not read
    thr = threshold[0]
    bad = 0
    for pl in range(p_):
        xp = x[pl]
        for q in range(-o, min(o, h + o)):
            inside = 0 <= q < h
            bad += ring_row(rows, q, size, depth, xp[q] if inside else empty, inside, w)
        for i in range(h):
            q = i + o
            bad += ring_row(rows, q, size, depth, xp[min(q, h - 1)], q < h, w)
            block_sums(ring, size, t, (i - o,), w, top[0, o : o + w], False)
            block_sums(ring, size, side, (i - o,), w, right[0, o : o + w], False)
            block_sums(ring, size, t, (i + g + 1,), w, bottom[0, o : o + w], False)
            block_sums(ring, size, side, (i - g,), w, left[0, o : o + w], False)
            _levels(top, ldepth, padded)
            _levels(bottom, ldepth, padded)
            _levels(right, sdepth, padded)
            _levels(left, sdepth, padded)
            block_sums(top, 0, side, (0,), w, sums[0], False)  # columns j - o .. j + g
            block_sums(right, 0, t, (o + g + 1,), w, sums[1], False)  # j + g + 1 .. j + o
            block_sums(bottom, 0, side, (o - g,), w, sums[2], False)  # j - g .. j + o
            block_sums(left, 0, t, (0,), w, sums[3], False)  # j - o .. j - g - 1
            nr0, nr1 = axis_count(i, h, -o, -g - 1), axis_count(i, h, -o, g)
            nr2, nr3 = axis_count(i, h, g + 1, o), axis_count(i, h, -g, o)
            xi, oi, mi, sc = xp[i], out[pl, i], mask[pl, i], scale[row_state[i]]
            cs = col_state
            c0, c1, c2, c3 = cols[0], cols[1], cols[2], cols[3]
            t0, t1, t2, t3 = sums[0], sums[1], sums[2], sums[3]
            lo, hi = 0, 0  # the columns where every block has the interior size
            if nr0 == t and nr1 == side and nr2 == t and nr3 == side and w > 2 * o:
                lo, hi = o, w - o
            for j in range(lo, hi):  # the interior: equal sizes, so the extreme sum's mean
                if is_max:
                    m = max(max(t0[j], t1[j]), max(t2[j], t3[j]))
                else:
                    m = min(min(t0[j], t1[j]), min(t2[j], t3[j]))
                est = m / (t * side)
                v = np.float64(xi[j]) / (est + 0.0)  # an estimate of -0.0 is 0
                oi[j] = 0.0 if v != v else v
            for j in range(w):
                if lo <= j < hi:
                    continue
                est = _extreme(
                    t0[j], t1[j], t2[j], t3[j],
                    nr0 * c0[j], nr1 * c1[j], nr2 * c2[j], nr3 * c3[j],
                    is_max,
                )  # fmt: skip
                v = np.float64(xi[j]) / (est + 0.0)
                f = sc[cs[j]]
                oi[j] = -np.inf if f == -np.inf else (0.0 if v != v else v) * f
            for j in range(w):
                mi[j] = oi[j] > thr
    return bad
