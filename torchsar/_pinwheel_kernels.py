"""numba kernels of the pinwheel-block CFARs (GO, SO, and VI without no-data): from the image
to the statistic in one sweep over its rows, with no full-size temporaries (with no-data,
GO and SO also give each block's count of valid cells, for the border factors).

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

from torchsar._block_sums import (
    JIT,
    axis_count,
    block_sums,
    kept_row,
    level_up,
    levels_for,
    pair_rings,
    pair_row,
    ring_row,
)

__all__ = [
    "block_ratio",
    "block_ratio_valid",
    "block_rows",
    "mean_of",
    "paired_pinwheel",
    "pinwheel_buffers",
    "pinwheel_sums",
    "ratio_of",
    "size_ranks",
    "vi_ratio",
    "vi_rule",
]

CA, GO, SO, CA_A, CA_B = range(5)  # VI's rules, in the order of its factor planes


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
def pinwheel_buffers(guard, train, w):
    """The working arrays of :func:`pinwheel_sums` for rows ``w`` long: the four blocks'
    column sums padded with ``o`` zeros a side and their levels ``(4, levels, w + 2o)``,
    and each block's in-image columns at each pixel ``(4, w)``."""
    g, o = guard, guard + train
    blocks = np.zeros((4, levels_for(o + g + 1), w + 2 * o))
    cols = np.zeros((4, w))
    for j in range(w):
        cols[0, j] = axis_count(j, w, -o, g)
        cols[1, j] = axis_count(j, w, g + 1, o)
        cols[2, j] = axis_count(j, w, -g, o)
        cols[3, j] = axis_count(j, w, -o, -g - 1)
    return blocks, cols


@njit(**JIT)
def paired_pinwheel(guard, train, w):
    """The working state of a kernel that sums two quantities over the four blocks: the
    window side, the row-block levels, the two rings of row blocks (:func:`pair_rings`),
    the blocks' buffers and in-image columns (:func:`pinwheel_buffers`) and the row's sums
    of each quantity ``(4, w)``."""
    o = guard + train
    size, depth = 2 * o + 1, levels_for(o + guard + 1)
    rows1, rows2, ring1, ring2 = pair_rings(depth, size, w)
    blocks, cols = pinwheel_buffers(guard, train, w)
    return size, depth, rows1, rows2, ring1, ring2, blocks, cols, np.zeros((4, w)), np.zeros((4, w))


@njit(**JIT)
def pinwheel_sums(ring, size, i, guard, train, blocks, sums):
    """The sums of the four blocks (top, right, bottom, left) at every pixel of row ``i``
    into ``sums`` ``(4, w)``, from the row-block ring ``ring`` (level ``k``, row ``r`` in
    row ``k size + r % size``): down each column, then along the row."""
    g, t, o = guard, train, guard + train
    side, w = o + g + 1, sums.shape[1]
    padded = blocks.shape[2]
    top, right, bottom, left = blocks[0], blocks[1], blocks[2], blocks[3]
    block_sums(ring, size, t, (i - o,), w, top[0, o : o + w], False)
    block_sums(ring, size, side, (i - o,), w, right[0, o : o + w], False)
    block_sums(ring, size, t, (i + g + 1,), w, bottom[0, o : o + w], False)
    block_sums(ring, size, side, (i - g,), w, left[0, o : o + w], False)
    _levels(top, levels_for(side), padded)
    _levels(bottom, levels_for(side), padded)
    _levels(right, levels_for(t), padded)
    _levels(left, levels_for(t), padded)
    block_sums(top, 0, side, (0,), w, sums[0], False)  # columns j - o .. j + g
    block_sums(right, 0, t, (o + g + 1,), w, sums[1], False)  # j + g + 1 .. j + o
    block_sums(bottom, 0, side, (o - g,), w, sums[2], False)  # j - g .. j + o
    block_sums(left, 0, t, (0,), w, sums[3], False)  # j - o .. j - g - 1


@njit(**JIT)
def block_ratio_valid(x, valid, guard, train, is_max, stat, counts):
    """:func:`block_ratio` over the valid cells (``valid`` uint8 ``(P, H, W)``) of each
    block: the blocks' valid values and their counts summed alike (two rings), into the
    float64 statistic ``x / extreme block mean`` ``stat`` ``(P, H, W)`` before the border
    factor, and each block's count ``counts`` ``(4, P, H, W)`` (top, right, bottom, left),
    from which the caller forms the factors and marks the pixels without a valid block
    cell, or not valid themselves.

    Returns how many values of ``x`` (valid or not) are not a finite number ``>= 0``."""
    p_, h, w = x.shape
    g, t, o = guard, train, guard + train
    size, depth, rows1, rows2, ring1, ring2, blocks, _, sums, cnts = paired_pinwheel(g, t, w)
    empty = x[0, 0] if p_ and h else np.zeros(w, x.dtype)  # a row not read
    bad = 0
    for pl in range(p_):
        xp, vp = x[pl], valid[pl]
        for q in range(-o, min(o, h + o)):
            inside = 0 <= q < h
            row, vrow = (xp[q] if inside else empty), vp[min(max(q, 0), h - 1)]
            bad += kept_row(rows1, rows2, q, depth, row, inside, np.inf, vrow, True)
        for i in range(h):
            q, qr = i + o, min(i + o, h - 1)
            bad += kept_row(rows1, rows2, q, depth, xp[qr], q < h, np.inf, vp[qr], True)
            pinwheel_sums(ring1, size, i, g, t, blocks, sums)
            pinwheel_sums(ring2, size, i, g, t, blocks, cnts)
            xi, si = xp[i], stat[pl, i]
            for j in range(w):
                est = _extreme(
                    sums[0, j], sums[1, j], sums[2, j], sums[3, j],
                    cnts[0, j], cnts[1, j], cnts[2, j], cnts[3, j],
                    is_max,
                )  # fmt: skip
                v = np.float64(xi[j]) / (est + 0.0)  # an estimate of -0.0 is 0
                si[j] = 0.0 if v != v else v
            for k in range(4):
                counts[k, pl, i] = cnts[k]
    return bad


@njit(**JIT, inline="always")
def block_rows(i, h, guard, train):
    """Each block's in-image rows at row ``i`` of ``h``."""
    g, o = guard, guard + train
    top, right = axis_count(i, h, -o, -g - 1), axis_count(i, h, -o, g)
    return top, right, axis_count(i, h, g + 1, o), axis_count(i, h, -g, o)


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
    blocks, cols = pinwheel_buffers(g, t, w)
    sums = np.zeros((4, w))
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
            pinwheel_sums(ring, size, i, g, t, blocks, sums)
            nr0, nr1, nr2, nr3 = block_rows(i, h, g, t)
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
                if not is_max and est == np.inf:  # as _extreme: SO's inf (an overflow) is 0
                    est = 0.0
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


@njit(**JIT, inline="always")
def mean_of(s1, count, shift):
    """:meth:`torchsar.windows.Sums.mean` of one cell."""
    if count > 0:
        return s1 / max(count, 1.0) + shift
    return 0.0


@njit(**JIT, inline="always")
def ratio_of(num, den):
    """:func:`torchsar.cfar.core.ratio` of one cell (``0 / 0 = 0``, never NaN; a ``-0.0``
    denominator is zero: ``den + 0.0`` is ``+0.0``)."""
    q = num / (den + 0.0)
    return 0.0 if q != q else q


@njit(**JIT, inline="always")
def _variable(n, s1, s2, mean, k_vi):
    """:func:`torchsar.cfar.vi._variable` of one half (``n`` cells, sums ``s1``, ``s2``)."""
    dof = n - 1.0
    m = s1 / max(n, 1.0)
    v = (s2 - m * s1) / max(dof, 1.0)
    var = (v if v > 0.0 else 0.0) if dof > 0 else 0.0
    vi = 1.0 + ratio_of(var, mean * mean)
    return vi > k_vi or n <= 1


@njit(**JIT, inline="always")
def vi_rule(x, halves, ring_s1, ring_n, shift, k_vi, k_mr):
    """VI-CFAR's rule (Smith & Varshney's decision table, as :func:`torchsar.cfar.vi`'s
    tensor code decides it) and statistic ``x / estimate`` (before the rule's factor) of
    one pixel: ``halves = (na, nb, a1, b1, a2, b2)``, half ``A``'s ``na`` cells and its
    sums ``a1``, ``a2`` of ``x - shift`` and its square, then ``B``'s; the ring's ``ring_n``
    cells sum to ``ring_s1``."""
    na, nb, a1, b1, a2, b2 = halves
    ma, mb = mean_of(a1, na, shift), mean_of(b1, nb, shift)
    var_a = _variable(na, a1, a2, ma, k_vi)
    var_b = _variable(nb, b1, b2, mb, k_vi)
    rule = GO if (ma > k_mr * mb) or (mb > k_mr * ma) else CA
    if var_a and not var_b:
        rule = CA_B
    if var_b and not var_a:
        rule = CA_A
    if var_a and var_b:
        rule = SO
    if na == 0 and nb > 0:
        rule = CA_B
    if nb == 0 and na > 0:
        rule = CA_A
    if rule == CA:
        est = mean_of(ring_s1, ring_n, shift)
    elif rule == GO:
        est = ma if ma >= mb else mb
    elif rule == SO:
        est = ma if ma <= mb else mb
    elif rule == CA_A:
        est = ma
    else:
        est = mb
    return rule, ratio_of(x, est)


@njit(**JIT)
def vi_ratio(x, guard, train, k_vi, k_mr, row_state, col_state, scale, threshold, out, mask):
    """VI-CFAR's statistic of every plane of ``x`` ``(P, H, W)`` into ``out`` (its dtype)
    and the decision ``out > threshold[0]`` into ``mask``: the halves are the top and right
    blocks (``A``) and the bottom and left ones (``B``), the ring all four; sums of ``x``
    and of its square, summed as :func:`block_ratio` sums; :func:`vi_rule`, then the rule's
    factor ``scale[rule, row_state[i], col_state[j]]`` (``-inf`` where no block has a
    cell).

    Returns how many values of ``x`` are not a finite number ``>= 0``."""
    p_, h, w = x.shape
    g, t, o = guard, train, guard + train
    size, depth, rows1, rows2, ring1, ring2, blocks, cols, s1, s2 = paired_pinwheel(g, t, w)
    empty = x[0, 0] if p_ and h else np.zeros(w, x.dtype)  # a row not read
    work = (ring1, ring2, size, blocks, cols, s1, s2)
    rule, states = (k_vi, k_mr, threshold[0]), (row_state, col_state, scale)
    bad = 0
    for pl in range(p_):
        xp = x[pl]
        for q in range(-o, min(o, h + o)):
            inside = 0 <= q < h
            row = xp[q] if inside else empty
            bad += pair_row(rows1, rows2, q, depth, row, inside)
        for i in range(h):
            q = i + o
            bad += pair_row(rows1, rows2, q, depth, xp[min(q, h - 1)], q < h)
            _vi_row(xp, i, g, t, work, rule, states, out[pl], mask[pl])
    return bad


@njit(**JIT)
def _vi_row(xp, i, g, t, work, rule, states, out, mask):
    """Row ``i`` of :func:`vi_ratio` (its window's rows in the rings; ``rule``: ``k_vi``,
    ``k_mr`` and the threshold; ``states``: the factor table and its row and column
    states)."""
    ring1, ring2, size, blocks, cols, s1, s2 = work
    k_vi, k_mr, thr = rule
    row_state, col_state, scale = states
    pinwheel_sums(ring1, size, i, g, t, blocks, s1)
    pinwheel_sums(ring2, size, i, g, t, blocks, s2)
    nr0, nr1, nr2, nr3 = block_rows(i, xp.shape[0], g, t)
    xi, oi, mi, rs = xp[i], out[i], mask[i], row_state[i]
    for j in range(xi.shape[0]):
        na = nr0 * cols[0, j] + nr1 * cols[1, j]
        nb = nr2 * cols[2, j] + nr3 * cols[3, j]
        a1, b1 = s1[0, j] + s1[1, j], s1[2, j] + s1[3, j]
        a2, b2 = s2[0, j] + s2[1, j], s2[2, j] + s2[3, j]
        halves = (na, nb, a1, b1, a2, b2)
        code, v = vi_rule(np.float64(xi[j]), halves, a1 + b1, na + nb, 0.0, k_vi, k_mr)
        f = scale[code, rs, col_state[j]]
        oi[j] = -np.inf if f == -np.inf else v * f
    for j in range(xi.shape[0]):
        mi[j] = oi[j] > thr


@njit(**JIT, inline="always")
def _sorted4(a, b, c, d):
    """The four values in ascending order (five compare-exchanges)."""
    a, b = min(a, b), max(a, b)
    c, d = min(c, d), max(c, d)
    a, c = min(a, c), max(a, c)
    b, d = min(b, d), max(b, d)
    b, c = min(b, c), max(b, c)
    return a, b, c, d


@njit(**JIT, inline="always")
def _size_rank(a, b, c, d):
    """The rank of the ascending sizes ``a <= b <= c <= d`` among all such tuples (the
    combinatorial number system of ``a < b + 1 < c + 2 < d + 3``): distinct tuples, distinct
    ranks."""
    x2, x3, x4 = b + 1, c + 2, d + 3  # each binomial divided as it grows (exact)
    return (
        a
        + x2 * (x2 - 1) // 2
        + x3 * (x3 - 1) // 2 * (x3 - 2) // 3
        + x4 * (x4 - 1) // 2 * (x4 - 2) // 3 * (x4 - 3) // 4
    )


@njit(**JIT)
def size_ranks(counts, interior):
    """Each pixel's rank of its ascending block sizes (``counts`` ``(4, N)``, float64 whole
    numbers; :func:`_size_rank`), ``-1`` where the sizes are the interior ones (in the
    blocks' order): the key of GO's and SO's border factor, which depends only on the
    sorted sizes."""
    out = np.empty(counts.shape[1], np.int64)
    for k in range(counts.shape[1]):
        a, b = np.int64(counts[0, k]), np.int64(counts[1, k])
        c, d = np.int64(counts[2, k]), np.int64(counts[3, k])
        if a == interior[0] and b == interior[1] and c == interior[2] and d == interior[3]:
            out[k] = -1
        else:
            a, b, c, d = _sorted4(a, b, c, d)
            out[k] = _size_rank(a, b, c, d)
    return out
