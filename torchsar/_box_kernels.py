"""numba kernels of the one-pass window statistics: CA-CFAR's ring-mean ratio and the
box-statistics speckle filters (Lee, Kuan, enhanced Lee) from the image to the result in
one sweep over its rows, with no full-size temporaries.

How the window sums are formed (fixed for every pixel by its position alone, so every
pixel's sums are the same float64 additions whatever the batch, tile or strip; no running
sum and no integral image, so nothing cancels: a bright target leaving the window leaves
no rounding residue behind):

- each image row is converted once to float64 and kept in a ring buffer of the window's
  rows;
- CA-CFAR (:func:`ring_ratio`) keeps, per row ``r``, the sums of rows ``r .. r + 2^k - 1``
  (one addition per level as each row arrives), adds a band of ``L`` rows as the blocks of
  ``L``'s binary digits, and does the same along the row: about a dozen additions per
  pixel, every one of non-negative terms;
- the speckle filters (:func:`box_filter`) sum the deviations of the window cells from each
  pixel's own value, column by column and then across (:func:`centred_sums`), so that their
  variances do not cancel either.

Interior sums are exact to a few float64 roundings (relative error below ``1e-14``
of the sum of the absolute values), where the integral images of
:func:`torchsar.windows.windowed` lose up to the integral's magnitude in cancellation; the
two paths agree to well within a float32 ulp (the tests bound the difference). Cells
outside the image count as absent (zero, and not in the count), as everywhere in torchsar.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

__all__ = [
    "axis_count",
    "box_filter",
    "centred_sums",
    "count_inverses",
    "exp_neg",
    "load",
    "moments",
    "ring_ratio",
]

_JIT = {"cache": True, "nogil": True, "error_model": "numpy", "boundscheck": False}


_MAGIC = 6755399441055744.0  # 1.5 * 2^52: adding it rounds to an integer in the low bits
_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01  # ln 2 in two parts (Cody and Waite)
_LN2_LO = 1.90821492927058770002e-10


@intrinsic
def _bits(typingctx, value):
    """The IEEE bits of a float64 as an int64."""

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.int64))

    return types.int64(types.float64), codegen


@intrinsic
def _float(typingctx, bits):
    """The float64 whose IEEE bits are the int64 ``bits``."""

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.float64))

    return types.float64(types.int64), codegen


@njit(**_JIT, inline="always")
def exp_neg(x):
    """``exp(x)`` for ``x <= 0`` (``-inf`` included), without a library call so that loops
    over it vectorise: ``x = k ln 2 + r``, ``|r| <= ln 2 / 2``, the Taylor polynomial of
    degree 13 in ``r`` (truncation below 1e-17) times ``2^k`` built from its bits. Results
    below the smallest normal double (``x < -708``) are 0."""
    xc = x if x > -708.0 else -708.0
    t = xc * _LOG2E + _MAGIC
    k = t - _MAGIC
    r = (xc - k * _LN2_HI) - k * _LN2_LO
    p = 1.0 / 6227020800.0
    p = p * r + 1.0 / 479001600.0
    p = p * r + 1.0 / 39916800.0
    p = p * r + 1.0 / 3628800.0
    p = p * r + 1.0 / 362880.0
    p = p * r + 1.0 / 40320.0
    p = p * r + 1.0 / 5040.0
    p = p * r + 1.0 / 720.0
    p = p * r + 1.0 / 120.0
    p = p * r + 1.0 / 24.0
    p = p * r + 1.0 / 6.0
    p = p * r + 0.5
    p = p * r + 1.0
    p = p * r + 1.0
    v = p * _float((_bits(t) - _bits(_MAGIC) + 1023) << 52)
    return v if x > -708.0 else 0.0


@njit(**_JIT)
def axis_count(i, n, lo, hi):
    """How many of the offsets ``lo..hi`` from ``i`` land in ``[0, n)``."""
    a = max(i + lo, 0)
    b = min(i + hi, n - 1)
    return max(b - a + 1, 0)


@njit(**_JIT)
def load(row, dst):
    """``dst = float64(row)``."""
    for j in range(row.shape[0]):
        dst[j] = np.float64(row[j])


@njit(**_JIT)
def levels_for(length):
    """How many block-sum levels a sum of ``length`` terms needs (``2^k <= length``)."""
    k = 0
    while (2 << k) <= length:
        k += 1
    return k + 1


@njit(**_JIT, inline="always")
def _level_up(lo, out, step, n):
    """``out[j] = lo[j] + lo[j + step]`` for ``j < n``: one level of block sums."""
    a, b, o = lo[:n], lo[step : step + n], out[:n]  # slices: j alone indexes (vectorises)
    for j in range(n):
        o[j] = a[j] + b[j]


@njit(**_JIT, inline="always")
def _put(a, b, n, out, first, pair):
    """``out[:n] (+)= a (+ b)``: assign when ``first``, add otherwise; ``b`` only when
    ``pair`` (two terms in one pass)."""
    o = out[:n]
    if pair:
        if first:
            for j in range(n):
                o[j] = a[j] + b[j]
        else:
            for j in range(n):
                o[j] += a[j] + b[j]
    elif first:
        for j in range(n):
            o[j] = a[j]
    else:
        for j in range(n):
            o[j] += a[j]


@njit(**_JIT, inline="always")
def _block_sums(src, size, length, starts, n, out, accumulate):
    """``out[j] (+)=`` the sums of ``length`` terms from each of ``starts`` (a tuple), from
    block sums of ``2^k`` terms: the blocks of ``length``'s set bits, largest first, start
    after start, two blocks per pass (a fixed association whatever ``j``). ``size == 0``:
    ``src[k, p + j]`` is the block of level ``k`` at ``p + j`` (along a row); else ``src``
    is a ring of ``size`` rows per level, the block starting at row ``p`` in row ``k size
    + p % size``."""
    first = not accumulate
    held, held_off = -1, 0
    for start in starts:
        pos = start
        k = levels_for(length) - 1
        while k >= 0:
            if (length >> k) & 1:
                row, off = (k * size + pos % size, 0) if size else (k, pos)
                if held < 0:
                    held, held_off = row, off
                else:
                    a = src[held, held_off : held_off + n]
                    _put(a, src[row, off : off + n], n, out, first, True)
                    first, held = False, -1
                pos += 1 << k
            k -= 1
    if held >= 0:
        a = src[held, held_off : held_off + n]
        _put(a, a, n, out, first, False)
    elif first:
        for j in range(n):
            out[j] = 0.0


@njit(**_JIT, inline="always")
def _row_levels(rows, q, size, depth, src, w):
    """Row ``q`` of the image (``src``, or zeros where ``src`` is empty) into the block-sum
    ring buffers ``rows[k, slot]`` (row ``r``'s sums of rows ``r .. r + 2^k - 1`` in slot
    ``r % size``), every level ending at ``q`` updated."""
    base = rows[0, q % size]
    if src.shape[0] == 0:
        for j in range(w):
            base[j] = 0.0
    else:
        for j in range(w):
            base[j] = np.float64(src[j])
    for k in range(1, depth):
        r = q - (1 << k) + 1
        half = 1 << (k - 1)
        a, b, dst = rows[k - 1, r % size], rows[k - 1, (r + half) % size], rows[k, r % size]
        for j in range(w):
            dst[j] = a[j] + b[j]


@njit(**_JIT)
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
    non-negative terms in an order fixed by the pixel's position alone."""
    p_, h, w = x.shape
    g, o = guard, guard + train
    size = 2 * o + 1
    n_full = size * size - (2 * g + 1) ** 2
    depth = levels_for(max(train, 2 * g + 1))
    rows = np.zeros((depth, size, w))
    ring = rows.reshape(depth * size, w)  # level k, row r in row k size + r % size
    hdepth, mdepth = levels_for(size), levels_for(train)
    band = np.zeros((hdepth, w + 2 * o))  # band rows summed, o zero columns a side, levels
    mid = np.zeros((mdepth, w + 2 * o))
    acc = np.zeros(w)
    empty = x[0, 0, :0] if p_ else np.zeros(0, x.dtype)
    outer_cols, guard_cols = np.zeros(w, np.int64), np.zeros(w, np.int64)
    for j in range(w):
        outer_cols[j] = axis_count(j, w, -o, o)
        guard_cols[j] = axis_count(j, w, -g, g)
    cf = np.ones(w)  # count times border factor
    thr = threshold[0]
    for pl in range(p_):
        xp = x[pl]
        for q in range(-o, min(o, h + o)):
            _row_levels(rows, q, size, depth, xp[q] if 0 <= q < h else empty, w)
        last_rows = (-1, -1)
        for i in range(h):
            q = i + o
            _row_levels(rows, q, size, depth, xp[q] if q < h else empty, w)
            counts = (axis_count(i, h, -o, o), axis_count(i, h, -g, g))
            if counts != last_rows:  # the counts and border factors of this row
                for j in range(w):
                    c = counts[0] * outer_cols[j] - counts[1] * guard_cols[j]
                    cf[j] = c * (scale[c] if c != n_full else 1.0)
                last_rows = counts
            b0, m0 = band[0, o : o + w], mid[0, o : o + w]
            _block_sums(ring, size, train, (i - o, i + g + 1), w, b0, False)  # top, bottom
            _block_sums(ring, size, 2 * g + 1, (i - g,), w, m0, False)
            for k in range(1, hdepth):
                n = w + 2 * o - (1 << k) + 1
                _level_up(band[k - 1], band[k], 1 << (k - 1), n)
                if k < mdepth:
                    _level_up(mid[k - 1], mid[k], 1 << (k - 1), n)
            _block_sums(band, 0, size, (0,), w, acc, False)
            _block_sums(mid, 0, train, (0, o + g + 1), w, acc, True)  # left, right
            xi, oi, mi = xp[i], out[pl, i], mask[pl, i]
            for j in range(w):
                v = np.float64(xi[j]) * cf[j] / (acc[j] + 0.0)  # a ring of -0.0 is 0
                oi[j] = v if v == v else 0.0
                mi[j] = oi[j] > thr


@njit(**_JIT)
def box_filter(x, radius, enhanced, cu2, weight_scale, damping, cmax2, out):
    """A box-statistics speckle filter of every plane of ``x`` ``(P, H, W)`` into ``out``:
    the window mean ``mu`` and ``Ci^2 = var / mu^2`` (population variance over the
    in-image cells, ``Ci^2`` clamped to ``[0, count - 1]``), then Lee / Kuan ``mu + W (I -
    mu)`` with ``W = clip((1 - cu2 / Ci^2) / weight_scale, 0, 1)``, or (``enhanced``)
    enhanced Lee ``I + W (mu - I)`` with ``W = exp(-h)``, ``h = damping (Ci - Cu) / (Cmax -
    Ci)`` (0 at or below ``Cu``, ``inf`` at or above ``Cmax``). Float64 throughout, cast
    once.

    The variance does not cancel (:func:`centred_sums`): a window of equal values has
    variance 0 exactly, wherever it lies."""
    p_, h, w = x.shape
    size = 2 * radius + 1
    wp = w + 2 * radius
    cache = np.zeros((size, w))
    cols_work = np.zeros((4, wp))
    t1, t2, tn = np.zeros(w), np.zeros(w), np.zeros(w)
    cols = np.zeros(w)
    for j in range(w):
        cols[j] = axis_count(j, w, -radius, radius)
    inv, cu2_over = np.zeros(w), np.zeros(w)
    cu, cmax = np.sqrt(cu2), np.sqrt(cmax2)
    for pl in range(p_):
        xp = x[pl]
        for r in range(min(radius, h)):
            load(xp[r], cache[r % size])
        last = -1
        for i in range(h):
            if i + radius < h:
                load(xp[i + radius], cache[(i + radius) % size])
            centre = cache[i % size]
            centred_sums(cache, i, h, radius, cols, cols_work, t1, t2, tn)
            last = count_inverses(i, h, radius, cols, cu2, last, inv, cu2_over)
            oi = out[pl, i]
            if enhanced:
                _enhanced_lee_row(xp[i], centre, t1, t2, tn, inv, cu, cmax, damping, oi)
            else:
                _lee_row(xp[i], centre, t1, t2, inv, cu2_over, cu2, weight_scale, oi)


@njit(**_JIT)
def centred_sums(cache, i, h, radius, cols, work, t1, t2, tn):
    """Sums of the deviations ``t1`` and squared deviations ``t2`` of the window cells of
    row ``i`` from each pixel's own value, and the window counts ``tn`` (the window rows
    are in ``cache``, row ``r`` in slot ``r % (2 radius + 1)``; ``cols`` the in-image
    columns of each pixel's window; ``work`` ``(4, W + 2 radius)`` scratch).

    Each column of the window is summed as deviations from its cell in row ``i``, then the
    columns' sums are moved to deviations from the pixel (``sum (x - C)^2 = S2 + d (2 S1 +
    n d)``, ``d`` the column's cell minus ``C``): since ``C`` is a cell of the window,
    ``(C - mean)^2`` is at most ``count`` times the variance and the variance ``(t2 - t1^2
    / n) / n`` loses at most a factor ``count`` of float64 precision."""
    size = 2 * radius + 1
    w = t1.shape[0]
    s1, s2, cc, nc = work[0], work[1], work[2], work[3]  # zero outside the image
    centre = cache[i % size]
    a1, a2 = s1[radius : radius + w], s2[radius : radius + w]
    ac, an = cc[radius : radius + w], nc[radius : radius + w]
    first, last = max(i - radius, 0), min(i + radius, h - 1)
    nv = np.float64(last - first + 1)
    for j in range(w):
        ac[j], an[j] = centre[j], nv
    r, init = first, True
    while r <= last:  # up to four window rows per pass
        k = min(4, last + 1 - r)
        _add_deviations(cache, size, r, k, centre, a1, a2, init)
        r, init = r + k, False
    c, init = 0, True
    while c < size:  # up to four window columns per pass
        k = min(4, size - c)
        _move_columns(s1, s2, cc, nc, c, k, centre, t1, t2, init)
        c, init = c + k, False
    for j in range(w):
        tn[j] = nv * cols[j]


@njit(**_JIT, inline="always")
def _add_deviations(cache, size, r, k, centre, a1, a2, init):
    """``a1 (+)= sum of (row - centre)``, ``a2 (+)= sum of (row - centre)^2`` over the
    ``k <= 4`` cached rows ``r .. r + k - 1`` (pairs added first: ``(a + b) + (c + d)``);
    ``init``: assign instead of add."""
    w = a1.shape[0]
    ra, rb = cache[r % size], cache[(r + min(k - 1, 1)) % size]
    rc, rd = cache[(r + min(k - 1, 2)) % size], cache[(r + min(k - 1, 3)) % size]
    for j in range(w):
        c = centre[j]
        da = ra[j] - c
        db = rb[j] - c if k > 1 else 0.0
        dc = rc[j] - c if k > 2 else 0.0
        dd = rd[j] - c if k > 3 else 0.0
        s1 = (da + db) + (dc + dd)
        s2 = (da * da + db * db) + (dc * dc + dd * dd)
        a1[j] = s1 if init else a1[j] + s1
        a2[j] = s2 if init else a2[j] + s2


@njit(**_JIT, inline="always")
def _column(s1, s2, cc, nc, c, w):
    """The four padded rows of :func:`centred_sums` from column ``c``, ``w`` long."""
    return s1[c : c + w], s2[c : c + w], cc[c : c + w], nc[c : c + w]


@njit(**_JIT, inline="always")
def _move_columns(s1, s2, cc, nc, c, k, centre, t1, t2, init):
    """``t1``, ``t2`` (+)= the ``k <= 4`` column sums from column ``c`` of the padded rows
    (``s1``, ``s2``: deviations from each column's cell ``cc`` in the pixel's row, ``nc``
    cells), moved to deviations from the pixel's value (``sum (x - C)^2 = S2 + d (2 S1 +
    n d)``, ``d = cc - C``); ``init``: assign instead of add."""
    w = t1.shape[0]
    last = k - 1  # columns past the k-th repeat it (their terms are dropped below)
    p1, p2, pc, pn = _column(s1, s2, cc, nc, c, w)
    q1, q2, qc, qn = _column(s1, s2, cc, nc, c + min(last, 1), w)
    u1, u2, uc, un = _column(s1, s2, cc, nc, c + min(last, 2), w)
    v1, v2, vc, vn = _column(s1, s2, cc, nc, c + min(last, 3), w)
    for j in range(w):
        ce = centre[j]
        dp = pc[j] - ce
        dq = qc[j] - ce
        du = uc[j] - ce
        dv = vc[j] - ce
        np_, nq, nu, nv_ = pn[j] * dp, qn[j] * dq, un[j] * du, vn[j] * dv
        x1p, x2p = p1[j] + np_, p2[j] + dp * (2.0 * p1[j] + np_)
        x1q = q1[j] + nq if k > 1 else 0.0
        x2q = q2[j] + dq * (2.0 * q1[j] + nq) if k > 1 else 0.0
        x1u = u1[j] + nu if k > 2 else 0.0
        x2u = u2[j] + du * (2.0 * u1[j] + nu) if k > 2 else 0.0
        x1v = v1[j] + nv_ if k > 3 else 0.0
        x2v = v2[j] + dv * (2.0 * v1[j] + nv_) if k > 3 else 0.0
        a = (x1p + x1q) + (x1u + x1v)
        b = (x2p + x2q) + (x2u + x2v)
        t1[j] = a if init else t1[j] + a
        t2[j] = b if init else t2[j] + b


@njit(**_JIT, inline="always")
def moments(c, t1, t2, n, inv):
    """Window mean (clamped at 0) and ``Ci^2`` (clamped to ``[0, n - 1]``) from the sums
    of deviations ``t1`` and squared deviations ``t2`` from the centre value ``c`` over
    ``n`` cells (``inv = 1 / n``)."""
    m1 = t1 * inv
    var = (t2 - t1 * m1) * inv
    var = var if var > 0.0 else 0.0
    mu = c + m1
    mu = mu if mu > 0.0 else 0.0
    # 0 / 0 is 0 and var / 0 is inf (clamped below), as in the torch code
    ci2 = var / (mu * mu) if mu > 0.0 else (0.0 if var == 0.0 else np.inf)
    return mu, (ci2 if ci2 < n - 1.0 else n - 1.0)


@njit(**_JIT)
def count_inverses(i, h, radius, cols, cu2, last, inv, cu2_over):
    """``inv = 1 / n`` and ``cu2_over = cu2 / (n - 1)`` of every window count ``n`` of row
    ``i`` (``cols``: each column's in-image window width), recomputed only when the
    window's in-image rows differ from ``last`` (they do only near the top and bottom);
    returns the row count."""
    nv = axis_count(i, h, -radius, radius)
    if nv != last:
        for j in range(inv.shape[0]):
            n = nv * cols[j]
            inv[j] = 1.0 / n
            cu2_over[j] = cu2 / (n - 1.0)
    return nv


@njit(**_JIT)
def _lee_row(xi, centre, t1, t2, inv, cu2_over, cu2, weight_scale, oi):
    """Lee / Kuan: ``mu + W (I - mu)``, ``W = clip((1 - cu2 / Ci^2) / weight_scale, 0, 1)``
    with ``Ci^2 = var / mu^2`` clamped to ``[0, n - 1]``: one division per pixel
    (``cu2 / Ci^2 = cu2 mu^2 / var``, at least ``cu2 / (n - 1)``; ``W = 0`` where the
    variance is 0)."""
    inv_ws = 1.0 / weight_scale
    for j in range(oi.shape[0]):
        m1 = t1[j] * inv[j]
        var = (t2[j] - t1[j] * m1) * inv[j]
        mu = centre[j] + m1
        mu = mu if mu > 0.0 else 0.0
        r = cu2 * (mu * mu) / var
        r = r if r > cu2_over[j] else cu2_over[j]
        wgt = (1.0 - r) * inv_ws if var > 0.0 else 0.0
        wgt = 0.0 if wgt < 0.0 else (1.0 if wgt > 1.0 else wgt)
        v = mu + wgt * (np.float64(xi[j]) - mu)
        oi[j] = v if v > 0.0 else 0.0  # a convex mix of values >= 0, but for rounding


@njit(**_JIT, fastmath={"contract"})  # a * b + c as one FMA (exp_neg's polynomial)
def _enhanced_lee_row(xi, centre, t1, t2, tn, inv, cu, cmax, damping, oi):
    """Enhanced Lee: ``I + W (mu - I)``, ``W = exp(-damping (Ci - Cu) / (Cmax - Ci))``, 1
    at or below ``Cu`` and 0 at or above ``Cmax``."""
    for j in range(oi.shape[0]):
        mu, ci2 = moments(centre[j], t1[j], t2[j], tn[j], inv[j])
        ci = np.sqrt(ci2)
        h = damping * (ci - cu) / (cmax - ci) if cu < ci < cmax else 0.0
        h = np.inf if ci >= cmax else h
        obs = np.float64(xi[j])
        v = obs + exp_neg(-h) * (mu - obs)
        oi[j] = v if v > 0.0 else 0.0  # a convex mix of values >= 0, but for rounding
