"""numba kernels of the one-pass window statistics: CA-CFAR's ring-mean ratio (with and
without no-data, and AC-CFAR's over its censored ring), the two-parameter CFAR's deviation
ratio and the box-statistics speckle filters (Lee, Kuan,
enhanced Lee) from the image to the result in one sweep over its rows, with no full-size
temporaries.

How the window sums are formed (fixed for every pixel by its position alone, so every
pixel's sums are the same float64 additions whatever the batch, tile or strip; no running
sum and no integral image, so nothing cancels: a bright target leaving the window leaves
no rounding residue behind): each image row is converted once to float64 and kept in a
ring buffer of the window's rows, with, per row ``r``, the sums of rows ``r .. r + 2^k -
1`` (one addition per level as each row arrives); a band of ``L`` rows is the blocks of
``L``'s binary digits, and so along the row (:mod:`torchsar._block_sums`).

- CA-CFAR (:func:`ring_ratio`) sums its ring as a top and a bottom band and the left and
  right parts of the middle rows: about a dozen additions per pixel, every one of
  non-negative terms; the sums are exact to a few float64 roundings (relative error below
  ``1e-14``), where the integral images of :func:`torchsar.windows.windowed` lose up to
  the integral's magnitude in cancellation; the two paths agree to well within a float32
  ulp (the tests bound the difference).
- CA-CFAR with no-data and AC-CFAR (:func:`kept_ratio`) sum the ring's *kept* cells (valid,
  and for AC at or below the censoring pre-threshold) the same way, with a second ring of
  their counts (a count is an exact sum); the border rule's factor then follows the count.
- the two-parameter CFAR (:func:`deviation_ratio`) sums its ring likewise, of ``x`` and
  its square (not shifted by the plane's mean, which bright targets far away would move),
  for the ring's mean and population variance; a near-flat ring (``n var < 2^-8 S2``, where that
  difference could cancel) is summed again from its cells, so a ring of equal cells has a
  variance of exactly 0 (the documented ``+inf`` / ``-inf`` / 0). With a no-data mask the
  ring's valid cells are summed and counted alike (a third ring of counts).
- the speckle filters (:func:`box_filter`) take the window mean and variance from the
  block sums of ``x`` and ``x^2``, near-flat windows summed again as deviations from the
  pixel (:mod:`torchsar._moment_kernels`: the variance within ``2^-38`` of its value, 0
  exactly for equal cells).

Cells outside the image count as absent (zero, and not in the count), as everywhere in
torchsar.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from torchsar._block_sums import (
    FMA,
    JIT,
    add_blocks,
    axis_count,
    block_list,
    block_sums,
    kept_row,
    level_up,
    levels_for,
    pair_rings,
    pair_row,
    ring_row,
    valid_row,
)
from torchsar._moment_kernels import (
    heterogeneity,
    moment_state,
    next_moments,
    prime,
    quick_heterogeneity,
)
from torchsar._vector_exp import exp_neg

__all__ = [
    "box_filter",
    "deviation_ratio",
    "kept_ratio",
    "moment_rings",
    "ring_buffers",
    "ring_moments",
    "ring_ratio",
    "ring_sums",
]


@njit(**JIT)
def ring_ratio(x, guard, train, scale, threshold, out, mask):
    """CA-CFAR's statistic ``x / mean_ring`` of every plane of ``x`` ``(P, H, W)`` into
    ``out`` (its dtype) and the decision ``out > threshold[0]`` (``threshold`` in ``out``'s
    dtype) into the bool ``mask``: the ring is the ``(2o+1)^2`` box minus the ``(2g+1)^2`` guard box
    (``o = g + t``), summed as its top and bottom bands plus the left and right parts of
    the middle rows (no subtraction), cells outside the image not counted; a pixel whose
    ring holds ``c != N`` cells is multiplied by ``scale[c]`` (the border rule's
    ``factor(N) / factor(c)``); ``0 / 0 = 0``.

    Each part is a sum of power-of-two blocks (rows ``r .. r + 2^k - 1`` kept per row as
    it arrives, then columns likewise): about a dozen additions per pixel, every one of
    non-negative terms in an order fixed by the pixel's position alone. The last additions
    along the row (:func:`ring_fold_plan`) are made in the loop that divides, so the row
    of ring sums is never written out.

    Returns how many values of ``x`` are not a finite number ``>= 0`` (the input check,
    made as the values are read; ``out`` and ``mask`` mean nothing unless 0)."""
    p_, h, w = x.shape
    g, o = guard, guard + train
    size = 2 * o + 1
    n_full = size * size - (2 * g + 1) ** 2
    depth = levels_for(max(train, 2 * g + 1))
    rows = np.zeros((depth, size, w))
    ring = rows.reshape(depth * size, w)  # level k, row r in row k size + r % size
    band, mid, levels = ring_buffers(guard, train, w)
    head, tail = ring_fold_plan(guard, train, band.shape[0], mid.shape[0])
    empty = x[0, 0] if p_ and h else np.zeros(w, x.dtype)  # a row not read
    outer_cols, guard_cols = np.zeros(w, np.int64), np.zeros(w, np.int64)
    for j in range(w):
        outer_cols[j] = axis_count(j, w, -o, o)
        guard_cols[j] = axis_count(j, w, -g, g)
    cf = np.ones(w)  # count times border factor
    thr = threshold[0]
    bad = 0
    for pl in range(p_):
        xp = x[pl]
        for q in range(-o, min(o, h + o)):
            inside = 0 <= q < h
            bad += ring_row(rows, q, size, depth, xp[q] if inside else empty, inside, w)
        last_rows = (-1, -1)
        for i in range(h):
            q = i + o
            bad += ring_row(rows, q, size, depth, xp[min(q, h - 1)], q < h, w)
            counts = (axis_count(i, h, -o, o), axis_count(i, h, -g, g))
            if counts != last_rows:  # the counts and border factors of this row
                for j in range(w):
                    c = counts[0] * outer_cols[j] - counts[1] * guard_cols[j]
                    cf[j] = c * (scale[c] if c != n_full else 1.0)
                last_rows = counts
            ring_levels_row(ring, size, i, g, train, band, mid)
            fold_head(levels, head, w)
            _ratio_row(levels, tail, xp[i], cf, thr, out[pl, i], mask[pl, i])
    return bad


@njit(**JIT)
def _ratio_row(levels, tail, xi, cf, thr, oi, mi):
    """One row of :func:`ring_ratio`: each pixel's ring sum as the left fold of the four
    pair terms ``tail`` (:func:`ring_fold_plan`) over ``levels``, then ``x cf / sum`` and
    the decision."""
    w = xi.shape[0]
    a0, a1 = levels[tail[0, 0], tail[0, 1] :], levels[tail[0, 2], tail[0, 3] :]
    b0, b1 = levels[tail[1, 0], tail[1, 1] :], levels[tail[1, 2], tail[1, 3] :]
    c0, c1 = levels[tail[2, 0], tail[2, 1] :], levels[tail[2, 2], tail[2, 3] :]
    d0, d1 = levels[tail[3, 0], tail[3, 1] :], levels[tail[3, 2], tail[3, 3] :]
    for j in range(w):
        acc = a0[j] + a1[j]
        acc += b0[j] + b1[j]
        acc += c0[j] + c1[j]
        acc += d0[j] + d1[j]
        v = np.float64(xi[j]) * cf[j] / (acc + 0.0)  # a ring of -0.0 is 0
        oi[j] = v if v == v else 0.0
        mi[j] = oi[j] > thr


@njit(**JIT)
def ring_buffers(guard, train, w):
    """The working rows of :func:`ring_sums` for rows ``w`` long (``o`` zero columns a
    side), in one array ``levels``: the top and bottom bands' column sums with their levels
    (``band``, rows ``0 ..``), the middle rows' (``mid``, the rows after), a row of zeros
    and a row for :func:`fold_head`. Returns ``band``, ``mid`` and ``levels``."""
    o = guard + train
    nb, nm = levels_for(2 * o + 1), levels_for(train)
    levels = np.zeros((nb + nm + 2, w + 2 * o))
    return levels[:nb], levels[nb : nb + nm], levels


@njit(**JIT)
def ring_fold_plan(guard, train, nb, nm, slots=4):
    """The ring sum of :func:`ring_sums` as a left fold of pair terms ``(row, position,
    row, position)`` over :func:`ring_buffers`' ``levels`` (``nb`` band and ``nm`` middle
    levels), term for term the additions of its two :func:`block_sums` calls (a block
    without a partner paired with the zero row; ``a + 0 = a``). Returns the terms to fold
    first (``head``, :func:`fold_head`; none unless there are more than ``slots``) and
    ``slots`` terms to fold in the loop that uses the sum (``tail``: when there is a head,
    its row first; padded with zero pairs)."""
    o = guard + train
    zero, pre = nb + nm, nb + nm + 1
    blocks = np.zeros((2 * 64 + 1, 2), np.int64)  # a length's set bits, for two starts
    terms = np.zeros((2 * 64, 4), np.int64)
    n = 0
    for part in range(2):  # the band, then both sides of the middle rows
        if part == 0:
            m = block_list(2 * o + 1, (0,), 0, blocks, 0)
        else:
            m = block_list(train, (0, o + guard + 1), nb, blocks, 0)
        blocks[m, 0], blocks[m, 1] = zero, 0  # the partner of an odd last block
        for b in range(0, m, 2):
            terms[n] = blocks[b, 0], blocks[b, 1], blocks[b + 1, 0], blocks[b + 1, 1]
            n += 1
    split = n - slots + 1 if n > slots else 0
    tail = np.zeros((slots, 4), np.int64)
    tail[:, 0], tail[:, 2] = zero, zero
    k = 0
    if split:
        tail[0, 0] = pre
        k = 1
    tail[k : k + n - split] = terms[split:n]
    return terms[:split].copy(), tail


@njit(**JIT)
def fold_head(levels, head, w):
    """The left fold of the pair terms ``head`` (:func:`ring_fold_plan`) of a row ``w``
    long into ``levels``' last row, as :func:`block_sums` adds them; nothing without
    terms."""
    out = levels[-1]
    for k in range(head.shape[0]):
        a = levels[head[k, 0], head[k, 1] : head[k, 1] + w]
        b = levels[head[k, 2], head[k, 3] : head[k, 3] + w]
        add_blocks(a, b, w, out, k == 0, True)


@njit(**JIT)
def paired_rings(guard, train, w):
    """The working state of a kernel that sums two quantities over the ring (values and
    squares, or kept values and counts): the outer half-width ``o``, the window side, the
    row-block levels, the two rings of row blocks (:func:`pair_rings`) and the row
    buffers of :func:`ring_sums`."""
    o = guard + train
    size = 2 * o + 1
    depth = levels_for(max(train, 2 * guard + 1))
    rows1, rows2, ring1, ring2 = pair_rings(depth, size, w)
    band, mid, _ = ring_buffers(guard, train, w)
    return o, size, depth, rows1, rows2, ring1, ring2, band, mid


@njit(**JIT)
def ring_levels_row(ring, size, i, guard, train, band, mid):
    """Row ``i``'s top and bottom bands' and middle rows' column sums from the row-block
    ring ``ring`` (level ``k``, row ``r`` in row ``k size + r % size``) into ``band[0]``
    and ``mid[0]``, and their block sums along the row into the higher levels."""
    g, o = guard, guard + train
    w = band.shape[1] - 2 * o
    b0, m0 = band[0, o : o + w], mid[0, o : o + w]
    block_sums(ring, size, train, (i - o, i + g + 1), w, b0, False)  # top, bottom
    block_sums(ring, size, 2 * g + 1, (i - g,), w, m0, False)
    for k in range(1, band.shape[0]):
        n = band.shape[1] - (1 << k) + 1
        level_up(band[k - 1], band[k], 1 << (k - 1), n)
        if k < mid.shape[0]:
            level_up(mid[k - 1], mid[k], 1 << (k - 1), n)


@njit(**JIT)
def ring_sums(ring, size, i, guard, train, band, mid, acc):
    """The ring sums of every pixel of row ``i`` into ``acc``, from the row-block ring
    ``ring`` (:func:`ring_levels_row`): the top and bottom bands and the left and right
    parts of the middle rows (no subtraction). Not inlined: inlined twice into a kernel it
    made numba compile it for 16 s instead of 3."""
    g, o, w = guard, guard + train, acc.shape[0]
    ring_levels_row(ring, size, i, guard, train, band, mid)
    block_sums(band, 0, 2 * o + 1, (0,), w, acc, False)
    block_sums(mid, 0, train, (0, o + g + 1), w, acc, True)  # left, right


@njit(**JIT)
def moment_rings(guard, train, w, has_valid):
    """The working state of a kernel that sums a row's values and their squares over the
    ring (:func:`_moment_row`): the guard and train widths, the row-block levels, the rings
    of values, squares and (``has_valid``) valid cells' counts, the row buffers of
    :func:`ring_sums`, each column's in-image outer and guard widths ``(2, w)``, and the
    row's sums and counts ``(3, w)``."""
    o, size, depth, rows1, rows2, ring1, ring2, band, mid = paired_rings(guard, train, w)
    rows3, _, ring3, _ = pair_rings(depth if has_valid else 1, size if has_valid else 1, w)
    cols = np.zeros((2, w))
    for j in range(w):
        cols[0, j] = axis_count(j, w, -o, o)
        cols[1, j] = axis_count(j, w, -guard, guard)
    rings = (ring1, ring2, ring3, size, band, mid)
    return guard, train, depth, rows1, rows2, rows3, rings, cols, np.zeros((3, w))


@njit(**JIT, inline="always")
def moment_views(state, has_valid):
    """The row's ring sums of the values and their squares and its counted cells in
    :func:`moment_rings`' state, and the rows of values and of counted-cell flags the
    near-flat rings are summed again from (:func:`_flat_moments`)."""
    sums, rows1, rows3 = state[-1], state[3], state[5]
    return sums[0], sums[1], sums[2], rows1[0], rows3[0] if has_valid else rows1[0]


@njit(**JIT)
def _moment_sweep(x, guard, train, has_valid):
    """What a kernel summing the values and squares of ``x`` ``(P, H, W)`` over the ring
    starts from: :func:`moment_rings`' state, its views (:func:`moment_views`) and a row
    of ``x``'s type to hand over where no image row is read."""
    w = x.shape[2]
    state = moment_rings(guard, train, w, has_valid)
    s1, s2, cnt, values, cells = moment_views(state, has_valid)
    empty = x[0, 0] if x.shape[0] and x.shape[1] else np.zeros(w, x.dtype)  # a row not read
    return state, s1, s2, cnt, values, cells, empty


@njit(**JIT)
def _prime_moments(state, xp, vp, empty, has_valid, r0):
    """The rows above row ``r0``'s window bottom into the rings of :func:`moment_rings`
    (zeros above the image); the count of bad values read."""
    g, t, depth, rows1, rows2, rows3 = state[0], state[1], state[2], state[3], state[4], state[5]
    o, h = g + t, xp.shape[0]
    bad = 0
    for q in range(r0 - o, min(r0 + o, h + o)):
        inside = 0 <= q < h
        row = xp[q] if inside else empty
        bad += _take(rows1, rows2, rows3, q, depth, row, vp, inside, has_valid)
    return bad


@njit(**JIT)
def _moment_row(state, xp, vp, i, has_valid):
    """Row ``i + o`` into the rings of :func:`moment_rings`, then row ``i``'s ring sums of
    the values and their squares and its counted cells into the state's sums ``(3, w)``
    (the counts geometric without ``has_valid``); the count of bad values read."""
    g, t, depth, rows1, rows2, rows3, rings, cols, sums = state
    ring1, ring2, ring3, size, band, mid = rings
    o, h, w = g + t, xp.shape[0], xp.shape[1]
    q = i + o
    bad = _take(rows1, rows2, rows3, q, depth, xp[min(q, h - 1)], vp, q < h, has_valid)
    ring_sums(ring1, size, i, g, t, band, mid, sums[0])
    ring_sums(ring2, size, i, g, t, band, mid, sums[1])
    cnt = sums[2]
    if has_valid:
        ring_sums(ring3, size, i, g, t, band, mid, cnt)
    else:
        ro, rg = axis_count(i, h, -o, o), axis_count(i, h, -g, g)
        for j in range(w):
            cnt[j] = ro * cols[0, j] - rg * cols[1, j]
    return bad


@njit(**JIT)
def deviation_ratio(x, valid, has_valid, guard, train, threshold, out, mask):
    """The two-parameter CFAR's statistic ``(x - mean_ring) / sigma_ring`` (population
    standard deviation) of every plane of ``x`` ``(P, H, W)`` into ``out`` (its dtype) and
    the decision ``out > threshold[0]`` into ``mask``: the ring sums of ``x`` and of its
    square, summed as :func:`ring_ratio` sums its ring; a ring of zero variance gives
    ``+inf`` above its mean, ``-inf`` below and 0 at it.

    With ``has_valid``, ``valid`` (uint8 ``(P, H, W)``) marks the cells that count: the
    ring's valid cells are summed and counted the same way (a count is an exact sum); a
    pixel with no valid ring cell, or not valid itself, gets ``-inf`` (never detected).

    Returns how many values of ``x`` are not a finite number ``>= 0``."""
    p_, h, w = x.shape
    g, o = guard, guard + train
    state, s1, s2, cnt, values, cells, empty = _moment_sweep(x, guard, train, has_valid)
    thr = threshold[0]
    bad = 0
    for pl in range(p_):
        xp, vp = x[pl], valid[pl if has_valid else 0]
        bad += _prime_moments(state, xp, vp, empty, has_valid, 0)
        for i in range(h):
            bad += _moment_row(state, xp, vp, i, has_valid)
            xi, oi, mi = xp[i], out[pl, i], mask[pl, i]
            flat = 0
            for j in range(w):
                c = max(cnt[j], 1.0)
                m = s1[j] / c
                var = s2[j] / c - m * m
                flat += c * var < _FLAT * s2[j]
                sigma = np.sqrt(var if var > 0.0 else 0.0)
                v = (np.float64(xi[j]) - m) / sigma
                oi[j] = 0.0 if v != v else v
            if flat:
                _near_flat_rings(values, cells, has_valid, i, h, g, o, s1, s2, xi, oi)
            if has_valid:
                vi = vp[i]
                for j in range(w):
                    if cnt[j] <= 0.0 or vi[j] == 0:
                        oi[j] = -np.inf
            for j in range(w):
                mi[j] = oi[j] > thr
    return bad


@njit(**JIT, inline="always")
def _take(rows1, rows2, rows3, q, depth, row, valid, present, has_valid):
    """Row ``q`` into the rings: values and squares (:func:`pair_row`), or with
    ``has_valid`` those of its valid cells (``valid``: the plane's flags) and their count
    (:func:`valid_row`)."""
    if has_valid:
        vrow = valid[min(max(q, 0), valid.shape[0] - 1)]  # not read where not present
        return valid_row(rows1, rows2, rows3, q, depth, row, vrow, present)
    return pair_row(rows1, rows2, q, depth, row, present)


@njit(**JIT)
def kept_ratio(
    x, valid, has_valid, limit, mu, guard, train, scale, global_factor, threshold, out, mask
):
    """The statistic ``x / mean`` over the ring's *kept* cells of every plane of ``x``
    ``(P, H, W)`` into ``out`` (its dtype) and the decision ``out > threshold[0]`` into
    ``mask``: the cells at or below the plane's ``limit[p]`` (AC-CFAR's censored ring;
    ``+inf`` keeps every cell, CA-CFAR's ring) and, with ``has_valid``, valid (``valid``
    uint8 ``(P, H, W)``), summed as :func:`ring_ratio` sums its ring, their count summed
    alike; times ``scale[c]`` for a ring of ``c`` such cells (the border rule's ``factor(N)
    / factor(c)``). A ring with no kept cell takes the global ratio ``(x / mu[p])
    global_factor`` where ``mu[p]`` is a number (AC), else ``-inf`` (``mu[p]`` NaN: CA); a
    pixel not valid itself is ``-inf`` (never detected).

    Returns how many values of ``x`` (valid or not) are not a finite number ``>= 0``."""
    p_, h, w = x.shape
    g = guard
    o, size, depth, rows1, rows2, ring1, ring2, band, mid = paired_rings(guard, train, w)
    s1, cnt = np.zeros(w), np.zeros(w)
    n_full = scale.shape[0] - 1
    empty = x[0, 0] if p_ and h else np.zeros(w, x.dtype)  # a row not read
    thr = threshold[0]
    bad = 0
    for pl in range(p_):
        xp, vp, lim, m = x[pl], valid[pl if has_valid else 0], limit[pl], mu[pl]
        last = vp.shape[0] - 1  # vp's rows are read only where valid (a dummy row else)
        for q in range(-o, min(o, h + o)):
            inside = 0 <= q < h
            row, vrow = (xp[q] if inside else empty), vp[min(max(q, 0), last)]
            bad += kept_row(rows1, rows2, q, depth, row, inside, lim, vrow, has_valid)
        for i in range(h):
            q, qr = i + o, min(i + o, h - 1)
            vrow = vp[min(qr, last)]
            bad += kept_row(rows1, rows2, q, depth, xp[qr], q < h, lim, vrow, has_valid)
            ring_sums(ring1, size, i, g, train, band, mid, s1)
            ring_sums(ring2, size, i, g, train, band, mid, cnt)
            xi, oi, mi = xp[i], out[pl, i], mask[pl, i]
            for j in range(w):
                c = cnt[j]
                v = np.float64(xi[j])
                if c > 0:
                    r = v / (s1[j] / c + 0.0)  # a mean of -0.0 is 0
                    r = 0.0 if r != r else r
                    k = int(c)
                    oi[j] = r * scale[k] if k != n_full else r
                elif m == m:  # every ring cell censored: the global ratio
                    r = v / m
                    oi[j] = (0.0 if r != r else r) * global_factor
                else:
                    oi[j] = -np.inf
            if has_valid:
                vi = vp[i]
                for j in range(w):
                    if vi[j] == 0:
                        oi[j] = -np.inf
            for j in range(w):
                mi[j] = oi[j] > thr
    return bad


_FLAT = 2.0**-8
"""A ring is near-flat where ``n var < 2^-8 S2`` (``S2`` its sum of squared deviations from
the plane's mean): only there can ``S2 / n - mean^2`` lose more than 8 bits."""


@njit(**JIT, inline="always")
def _counted(vcache, has_valid, i, j, g, r, k):
    """Whether cell ``(r, k)`` is a counted cell of pixel ``(i, j)``'s ring (outside the
    guard box and, with ``has_valid``, valid: ``vcache`` holds 1 for a valid cell)."""
    if abs(r - i) <= g and abs(k - j) <= g:
        return False
    return not has_valid or vcache[r % vcache.shape[0], k] > 0.0


@njit(**JIT)
def _flat_moments(cache, vcache, has_valid, i, j, h, g, o, s1, s2):
    """Pixel ``(i, j)``'s ring moments again from its counted cells where the sums ``s1``,
    ``s2`` make the ring near-flat (in-image cells, and valid with ``has_valid``; ``cache``:
    the rows of ``x``, row ``r`` in slot ``r % size``; ``vcache``: their valid flags): the
    deviations from the ring's first counted cell ``base``, then from their mean ``m``, in
    two passes. Returns ``(near_flat, base, m, var)``, the population variance exactly 0
    for equal cells; ``near_flat`` false (the rest unset) where the sums do."""
    size, w = cache.shape[0], cache.shape[1]
    r0, r1 = max(i - o, 0), min(i + o, h - 1)
    c0, c1 = max(j - o, 0), min(j + o, w - 1)
    n, base = 0, 0.0
    for r in range(r0, r1 + 1):
        for k in range(c0, c1 + 1):
            if _counted(vcache, has_valid, i, j, g, r, k):
                base = cache[r % size, k] if n == 0 else base
                n += 1
    if n <= 0 or n * (s2 / n - (s1 / n) ** 2) >= _FLAT * s2:
        return False, 0.0, 0.0, 0.0
    t1 = 0.0
    for r in range(r0, r1 + 1):
        row = cache[r % size]
        for k in range(c0, c1 + 1):
            if _counted(vcache, has_valid, i, j, g, r, k):
                t1 += row[k] - base
    m = t1 / n
    e1, e2 = 0.0, 0.0
    for r in range(r0, r1 + 1):
        row = cache[r % size]
        for k in range(c0, c1 + 1):
            if _counted(vcache, has_valid, i, j, g, r, k):
                e = (row[k] - base) - m
                e1 += e
                e2 += e * e
    return True, base, m, (e2 - e1 * (e1 / n)) / n


@njit(**JIT)
def _near_flat_rings(cache, vcache, has_valid, i, h, g, o, s1, s2, xi, oi):
    """Row ``i``'s statistic (of ``h`` rows) where the ring is near-flat, from its counted
    cells (:func:`_flat_moments`). Equal cells give a variance of exactly 0: ``+inf``
    above their value, ``-inf`` below, 0 at it."""
    for j in range(oi.shape[0]):
        flat, base, m, var = _flat_moments(cache, vcache, has_valid, i, j, h, g, o, s1[j], s2[j])
        if not flat:
            continue
        sigma = np.sqrt(var if var > 0.0 else 0.0)
        v = (np.float64(xi[j]) - (base + m)) / sigma
        oi[j] = 0.0 if v != v else v


@njit(**JIT)
def ring_moments(x, valid, has_valid, guard, train, r0, count, mean, var):
    """The ring's cell count, mean and population variance at every pixel of rows ``r0 ..
    r0 + R - 1`` of every plane of ``x`` ``(P, H, W)`` (float64, any sign, finite: checked
    by the caller) into the float64 ``count``, ``mean``, ``var`` ``(P, R, W)``: the ring
    sums of ``x`` and of its square summed as :func:`ring_ratio` sums its ring (only the
    valid cells, also counted, with ``has_valid``: ``valid`` uint8 ``(P, H, W)``); a
    near-flat ring (``n var < 2^-8 S2``) from its cells again (:func:`_flat_moments`):
    equal cells give a variance of exactly 0. A ring without a counted cell: count 0, mean
    and variance 0."""
    p_, h, w = x.shape
    g, o = guard, guard + train
    state, s1, s2, cnt, values, cells, empty = _moment_sweep(x, guard, train, has_valid)
    for pl in range(p_):
        xp, vp = x[pl], valid[pl if has_valid else 0]
        _prime_moments(state, xp, vp, empty, has_valid, r0)
        for i in range(r0, r0 + count.shape[1]):
            _moment_row(state, xp, vp, i, has_valid)
            ci, mi, vi = count[pl, i - r0], mean[pl, i - r0], var[pl, i - r0]
            for j in range(w):
                c = cnt[j]
                m = s1[j] / max(c, 1.0)
                v = s2[j] / max(c, 1.0) - m * m
                ci[j] = c
                mi[j] = m
                vi[j] = v if v > 0.0 else 0.0
            for j in range(w):
                if cnt[j] > 0 and cnt[j] * (s2[j] / cnt[j] - mi[j] * mi[j]) < _FLAT * s2[j]:
                    flat, base, m, v = _flat_moments(
                        values, cells, has_valid, i, j, h, g, o, s1[j], s2[j]
                    )
                    if flat:
                        mi[j] = base + m
                        vi[j] = v if v > 0.0 else 0.0


@njit(**JIT)
def box_filter(x, radius, enhanced, cu2, weight_scale, damping, cmax2, out):
    """A box-statistics speckle filter of every plane of ``x`` ``(P, H, W)`` into ``out``:
    the window mean ``mu`` and ``Ci^2 = var / mu^2`` (population variance over the
    in-image cells, ``Ci^2`` clamped to ``[0, count - 1]``), then Lee / Kuan ``mu + W (I -
    mu)`` with ``W = clip((1 - cu2 / Ci^2) / weight_scale, 0, 1)``, or (``enhanced``)
    enhanced Lee ``I + W (mu - I)`` with ``W = exp(-h)``, ``h = damping (Ci - Cu) / (Cmax -
    Ci)`` (0 at or below ``Cu``, ``inf`` at or above ``Cmax``). Float64 throughout, cast
    once; the moments are :func:`torchsar._moment_kernels.row_moments`' (a window of equal
    values has variance 0 exactly).

    Returns how many values of ``x`` are not a finite number ``>= 0`` (the input check,
    made as the values are read; ``out`` means nothing unless 0)."""
    p_, h, w = x.shape
    state = moment_state(radius, w)
    cache, counts, mu, var = state[0], state[4], state[5], state[6]
    cu, cmax = np.sqrt(cu2), np.sqrt(cmax2)
    bad = 0
    for pl in range(p_):
        xp = x[pl]
        bad += prime(cache, xp, radius)
        last = -1
        for i in range(h):
            b, last = next_moments(state, xp, i, radius, cu2, last)
            bad += b
            oi = out[pl, i]
            if enhanced:
                _enhanced_lee_row(xp[i], mu, var, counts[0], cu, cmax, damping, oi)
            else:
                _lee_row(xp[i], mu, var, counts[2], cu2, weight_scale, oi)
    return bad


@njit(**JIT)
def _lee_row(xi, mu, var, cu2_over, cu2, weight_scale, oi):
    """Lee / Kuan: ``mu + W (I - mu)``, ``W = clip((1 - cu2 / Ci^2) / weight_scale, 0, 1)``
    with ``Ci^2 = var / mu^2`` clamped to ``[0, n - 1]``: one division per pixel
    (``cu2 / Ci^2 = cu2 mu^2 / var``, at least ``cu2 / (n - 1)``; ``W = 0`` where the
    variance is 0)."""
    inv_ws = 1.0 / weight_scale
    for j in range(oi.shape[0]):
        m, v = mu[j], var[j]
        r = cu2 * (m * m) / v
        r = r if r > cu2_over[j] else cu2_over[j]
        wgt = (1.0 - r) * inv_ws if v > 0.0 else 0.0
        wgt = 0.0 if wgt < 0.0 else (1.0 if wgt > 1.0 else wgt)
        o = m + wgt * (np.float64(xi[j]) - m)
        oi[j] = o if o > 0.0 else 0.0  # a convex mix of values >= 0, but for rounding


@njit(**FMA)  # exp_neg's polynomial with FMAs
def _enhanced_lee_row(xi, mu, var, tn, cu, cmax, damping, oi):
    """Enhanced Lee: ``I + W (mu - I)``, ``W = exp(-damping (Ci - Cu) / (Cmax - Ci))``, 1
    at or below ``Cu`` and 0 at or above ``Cmax`` (``tn``: the window counts). The row by
    :func:`~torchsar._moment_kernels.quick_heterogeneity` (vectorised), its doubtful
    pixels again by :func:`~torchsar._moment_kernels.heterogeneity`."""
    doubtful = 0
    for j in range(oi.shape[0]):
        h, doubt = quick_heterogeneity(mu[j], var[j], tn[j], cu, cmax, damping)
        doubtful += doubt
        oi[j] = _enhanced_lee(xi[j], mu[j], h)
    if doubtful:
        for j in range(oi.shape[0]):
            if quick_heterogeneity(mu[j], var[j], tn[j], cu, cmax, damping)[1]:
                h = heterogeneity(mu[j], var[j], tn[j], cu, cmax, damping)
                oi[j] = _enhanced_lee(xi[j], mu[j], h)


@njit(**FMA, inline="always")
def _enhanced_lee(obs, mu, h):
    """``I + exp(-h) (mu - I)`` in float64, at least 0 (a convex mix of values >= 0, but
    for rounding)."""
    x = np.float64(obs)
    o = x + exp_neg(-(h)) * (mu - x)
    return o if o > 0.0 else 0.0
