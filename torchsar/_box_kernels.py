"""numba kernels of the one-pass window statistics: CA-CFAR's ring-mean ratio and the
box-statistics speckle filters (Lee, Kuan, enhanced Lee) from the image to the result in
one sweep over its rows, with no full-size temporaries.

How the window sums are formed (the same for every kernel here, so every pixel's sums are
a fixed sequence of float64 additions, whatever the batch, tile or strip):

- each image row is converted once to float64 and kept in a ring buffer of the window's
  rows;
- the column sums of an output row add those rows from the top, four at a time (*direct*
  sums: no running sum, no integral image, so no cancellation: a bright target leaving the
  window leaves no rounding residue behind);
- the row sums of those column sums add the columns from the left, four at a time. The
  speckle filters' variances sum deviations instead of values so that nothing cancels
  (:func:`box_filter`).

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
def _add_rows(cache, first, last, h, size, dst):
    """``dst[:] = sum of the cached rows first..last`` (inside ``[0, h)``), in groups of four
    rows from the top (``(a + b) + (c + d)``, then the rest one by one); the cache holds row
    ``r`` in slot ``r % size``."""
    w = dst.shape[0]
    lo, hi = max(first, 0), min(last, h - 1) + 1
    for j in range(w):
        dst[j] = 0.0
    r = lo
    while r + 4 <= hi:
        a, b = cache[r % size], cache[(r + 1) % size]
        c, d = cache[(r + 2) % size], cache[(r + 3) % size]
        for j in range(w):
            dst[j] += (a[j] + b[j]) + (c[j] + d[j])
        r += 4
    while r < hi:
        a = cache[r % size]
        for j in range(w):
            dst[j] += a[j]
        r += 1


@njit(**_JIT)
def _row_box(v, width, out):
    """``out[j] = v[j] + ... + v[j + width - 1]`` for every ``j < len(out)``: the terms
    four at a time from the left (``(a + b) + (c + d)``), then the rest one by one (one
    vectorised pass per group)."""
    w = out.shape[0]
    for j in range(w):
        out[j] = 0.0
    c = 0
    while c + 4 <= width:
        a, b = v[c : c + w], v[c + 1 : c + 1 + w]
        d, e = v[c + 2 : c + 2 + w], v[c + 3 : c + 3 + w]
        for j in range(w):
            out[j] += (a[j] + b[j]) + (d[j] + e[j])
        c += 4
    while c < width:
        a = v[c : c + w]
        for j in range(w):
            out[j] += a[j]
        c += 1


@njit(**_JIT)
def load(row, dst):
    """``dst = float64(row)``."""
    for j in range(row.shape[0]):
        dst[j] = np.float64(row[j])


@njit(**_JIT)
def ring_ratio(x, guard, train, scale, out):
    """CA-CFAR's statistic ``x / mean_ring`` of every plane of ``x`` ``(P, H, W)`` into
    ``out`` (its dtype): the ring is the ``(2o+1)^2`` box minus the ``(2g+1)^2`` guard box
    (``o = g + t``), summed as its top and bottom bands plus the left and right parts of
    the middle rows (no subtraction), cells outside the image not counted; a pixel whose
    ring holds ``c != N`` cells is multiplied by ``scale[c]`` (the border rule's
    ``factor(N) / factor(c)``); ``0 / 0 = 0``."""
    p_, h, w = x.shape
    g, o = guard, guard + train
    size = 2 * o + 1
    n_full = size * size - (2 * g + 1) ** 2
    cache = np.zeros((size, w))
    band = np.zeros(w + 2 * o)  # rows of the top and bottom bands, o zero columns a side
    mid = np.zeros(w + 2 * o)  # the 2g+1 middle rows
    acc, part = np.zeros(w), np.zeros(w)
    outer_cols, guard_cols = np.zeros(w, np.int64), np.zeros(w, np.int64)
    for j in range(w):
        outer_cols[j] = axis_count(j, w, -o, o)
        guard_cols[j] = axis_count(j, w, -g, g)
    count, factor = np.zeros(w), np.ones(w)
    for pl in range(p_):
        xp = x[pl]
        for r in range(min(o, h)):
            load(xp[r], cache[r % size])
        last_rows = (-1, -1)
        for i in range(h):
            if i + o < h:
                load(xp[i + o], cache[(i + o) % size])
            rows = (axis_count(i, h, -o, o), axis_count(i, h, -g, g))
            if rows != last_rows:  # the counts and border factors of this row
                for j in range(w):
                    c = rows[0] * outer_cols[j] - rows[1] * guard_cols[j]
                    count[j] = c
                    factor[j] = scale[c] if c != n_full else 1.0
                last_rows = rows
            inner = band[o : o + w]
            _add_rows(cache, i - o, i - g - 1, h, size, inner)
            _add_rows(cache, i + g + 1, i + o, h, size, part)
            for j in range(w):
                inner[j] += part[j]
            _add_rows(cache, i - g, i + g, h, size, mid[o : o + w])
            _row_box(band, size, acc)
            _row_box(mid, train, part)
            for j in range(w):
                acc[j] += part[j]
            _row_box(mid[o + g + 1 :], train, part)
            xi, oi = xp[i], out[pl, i]
            for j in range(w):
                v = np.float64(xi[j]) / ((acc[j] + part[j]) / count[j]) * factor[j]
                oi[j] = v if v == v else 0.0


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
    cu, cmax = np.sqrt(cu2), np.sqrt(cmax2)
    for pl in range(p_):
        xp = x[pl]
        for r in range(min(radius, h)):
            load(xp[r], cache[r % size])
        for i in range(h):
            if i + radius < h:
                load(xp[i + radius], cache[(i + radius) % size])
            centre = cache[i % size]
            centred_sums(cache, i, h, radius, cols, cols_work, t1, t2, tn)
            if enhanced:
                _enhanced_lee_row(xp[i], centre, t1, t2, tn, cu, cmax, damping, out[pl, i])
            else:
                _lee_row(xp[i], centre, t1, t2, tn, cu2, weight_scale, out[pl, i])


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
        a1[j], a2[j], ac[j], an[j] = 0.0, 0.0, centre[j], nv
    for r in range(first, last + 1):
        src = cache[r % size]
        for j in range(w):
            d = src[j] - centre[j]
            a1[j] += d
            a2[j] += d * d
    for j in range(w):
        t1[j], t2[j], tn[j] = 0.0, 0.0, nv * cols[j]
    for c in range(size):
        b1, b2, bc, bn = s1[c : c + w], s2[c : c + w], cc[c : c + w], nc[c : c + w]
        for j in range(w):
            d = bc[j] - centre[j]
            nd = bn[j] * d
            t1[j] += b1[j] + nd
            t2[j] += b2[j] + d * (2.0 * b1[j] + nd)


@njit(**_JIT, inline="always")
def moments(c, t1, t2, n):
    """Window mean (clamped at 0) and ``Ci^2`` (clamped to ``[0, n - 1]``) from the sums
    of deviations ``t1`` and squared deviations ``t2`` from the centre value ``c``."""
    m1 = t1 / n
    var = (t2 - t1 * m1) / n
    var = var if var > 0.0 else 0.0
    mu = c + m1
    mu = mu if mu > 0.0 else 0.0
    # 0 / 0 is 0 and var / 0 is inf (clamped below), as in the torch code
    ci2 = var / (mu * mu) if mu > 0.0 else (0.0 if var == 0.0 else np.inf)
    return mu, (ci2 if ci2 < n - 1.0 else n - 1.0)


@njit(**_JIT)
def _lee_row(xi, centre, t1, t2, tn, cu2, weight_scale, oi):
    """Lee / Kuan: ``mu + W (I - mu)``, ``W = clip((1 - cu2 / Ci^2) / weight_scale, 0, 1)``."""
    for j in range(oi.shape[0]):
        mu, ci2 = moments(centre[j], t1[j], t2[j], tn[j])
        wgt = (1.0 - cu2 / ci2) / weight_scale if ci2 > 0.0 else 0.0
        wgt = 0.0 if wgt < 0.0 else (1.0 if wgt > 1.0 else wgt)
        oi[j] = mu + wgt * (np.float64(xi[j]) - mu)


@njit(**_JIT, fastmath={"contract"})  # a * b + c as one FMA (exp_neg's polynomial)
def _enhanced_lee_row(xi, centre, t1, t2, tn, cu, cmax, damping, oi):
    """Enhanced Lee: ``I + W (mu - I)``, ``W = exp(-damping (Ci - Cu) / (Cmax - Ci))``, 1
    at or below ``Cu`` and 0 at or above ``Cmax``."""
    for j in range(oi.shape[0]):
        mu, ci2 = moments(centre[j], t1[j], t2[j], tn[j])
        ci = np.sqrt(ci2)
        h = damping * (ci - cu) / (cmax - ci) if cu < ci < cmax else 0.0
        h = np.inf if ci >= cmax else h
        obs = np.float64(xi[j])
        oi[j] = obs + exp_neg(-h) * (mu - obs)
