"""numba kernels of the window mean and variance of every pixel of an image row, for the
one-sweep speckle filters (:func:`torchsar._box_kernels.box_filter`,
:func:`torchsar._shell_kernels.frost_filter`).

How they are formed:

- each image row is converted once to float64 and kept in a ring buffer of the window's
  rows (rows outside the image are zeros);
- the column sums ``sum x`` and ``sum x^2`` down the window's rows, then the window sums
  ``S1``, ``S2`` along the row, each as groups of four terms ``(a + b) + (c + d)`` added in
  turn: all terms non-negative, in an order fixed by the pixel's position alone (no running
  sum and no integral image: a bright target leaving the window leaves no rounding
  residue behind, and the result does not depend on the batch, tile or strip), and the
  working rows small enough to stay in the first-level cache;
- the variance is ``(S2 - S1^2 / n) / n``. With ``L = 2 (ceil(size / 4) + 2)`` additions
  at most on any term's way into a sum, its error is at most ``(3 L + 4) u S2 / n`` (``u =
  2^-53``). Where that could matter, the window is *near-flat*, ``n var < 2^-8 S2`` (a
  coefficient of variation under about 1/16), and its row is summed again as deviations
  from each pixel's own value ``C``, column by column (vectorised: a near-flat image costs
  two to three times a speckled one); where ``C`` lies far from the window's mean
  (``(1 + (C - mean)^2 / var) n > 2^13``) the pixel's cells are summed once more, in two
  passes (:func:`_centred`). A window of equal values has variance 0 exactly. Everywhere
  the variance is then within ``(3 L + 4) 2^-45``, about ``2^-40`` or ``(n + 3) u`` of its
  value, relative: below ``2^-38`` for windows up to 63 x 63 (tested against exact sums
  up to 31 x 31).

Cells outside the image count as absent (zero, and not in the count), as everywhere in
torchsar. Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from torchsar._block_sums import JIT, axis_count, take_row

__all__ = [
    "FLAT",
    "ci2_of",
    "heterogeneity",
    "moment_buffers",
    "moment_state",
    "next_moments",
    "next_row",
    "prime",
    "quick_heterogeneity",
    "row_moments",
    "window_counts",
]


FLAT = 2.0**-8  # n var below FLAT * sum x^2: near-flat, summed again as deviations
_SPREAD = 2.0**13  # centred sums taken where (1 + (C - mean)^2 / var) n <= 2^13


@njit(**JIT)
def moment_buffers(radius, w):
    """The working arrays of a ``(2 radius + 1)^2`` window over rows ``w`` long: the rows
    ring ``(size, w)`` (row ``r`` in slot ``r % size``), the column sums of ``x`` and
    ``x^2`` padded with ``radius`` zeros a side, and the window sums ``(4, w)`` (``S1``,
    ``S2``, then the near-flat rows' sums of deviations: :func:`centred_sums` uses all four
    padded rows ``(4, w + 2 radius)``)."""
    size = 2 * radius + 1
    return np.zeros((size, w)), np.zeros((4, w + 2 * radius)), np.zeros((4, w))


@njit(**JIT)
def prime(cache, xp, radius):
    """Rows ``-radius .. radius - 1`` of the plane ``xp`` into the ring (before row 0); the
    count of values that are not a finite number ``>= 0``."""
    h = xp.shape[0]
    bad = 0
    for q in range(-radius, radius):
        bad += take_row(cache, q, xp[max(min(q, h - 1), 0)], 0 <= q < h)
    return bad


@njit(**JIT)
def next_row(cache, xp, i, radius):
    """Row ``i + radius`` into the ring (zeros past the bottom): row ``i``'s window is then
    complete. The count of its values that are not a finite number ``>= 0``."""
    h = xp.shape[0]
    q = i + radius
    return take_row(cache, q, xp[min(q, h - 1)], q < h)


@njit(**JIT, inline="always")
def _sum4(a, b, c, d, k):
    """``(a + b) + (c + d)`` of the first ``k`` of the four (the others as 0)."""
    b = b if k > 1 else 0.0
    c = c if k > 2 else 0.0
    d = d if k > 3 else 0.0
    return (a + b) + (c + d)


@njit(**JIT, inline="always")
def _four(a, b, c, d, k):
    """:func:`_sum4` of the four and of their squares."""
    return _sum4(a, b, c, d, k), _sum4(a * a, b * b, c * c, d * d, k)


@njit(**JIT)
def _down(cache, first, size, k, o1, o2, init):
    """``o1 (+)= sum x``, ``o2 (+)= sum x^2`` over the ``k <= 4`` ring rows from row
    ``first``; ``init``: assign instead of add."""
    ra, rb = cache[first % size], cache[(first + min(k - 1, 1)) % size]
    rc, rd = cache[(first + min(k - 1, 2)) % size], cache[(first + min(k - 1, 3)) % size]
    for j in range(o1.shape[0]):
        s1, s2 = _four(ra[j], rb[j], rc[j], rd[j], k)
        o1[j] = s1 if init else o1[j] + s1
        o2[j] = s2 if init else o2[j] + s2


@njit(**JIT, inline="always")
def _at(c, start, k, m, w):
    """The ``m``-th of ``k`` consecutive ``w``-long windows of ``c`` from ``start`` (the
    last one again past ``k``)."""
    o = start + min(k - 1, m)
    return c[o : o + w]


@njit(**JIT)
def _across(c1, c2, start, k, t1, t2, init):
    """``t1 (+)=`` the sums of the ``k <= 4`` padded column sums ``c1`` from ``j + start``
    (and ``t2`` of ``c2``); ``init``: assign instead of add."""
    w = t1.shape[0]
    a1, b1, e1, d1 = (
        _at(c1, start, k, 0, w),
        _at(c1, start, k, 1, w),
        _at(c1, start, k, 2, w),
        _at(c1, start, k, 3, w),
    )
    a2, b2, e2, d2 = (
        _at(c2, start, k, 0, w),
        _at(c2, start, k, 1, w),
        _at(c2, start, k, 2, w),
        _at(c2, start, k, 3, w),
    )
    for j in range(w):
        x1 = _sum4(a1[j], b1[j], e1[j], d1[j], k)
        x2 = _sum4(a2[j], b2[j], e2[j], d2[j], k)
        t1[j] = x1 if init else t1[j] + x1
        t2[j] = x2 if init else t2[j] + x2


@njit(**JIT)
def moment_state(radius, w):
    """What :func:`next_moments` keeps for rows ``w`` long: the buffers of
    :func:`moment_buffers` (the rows ring first), each column's in-image window width, the
    rows of :func:`window_counts`, and the row's window means and variances."""
    cache, pad, sums = moment_buffers(radius, w)
    cols = np.zeros(w)
    for j in range(w):
        cols[j] = axis_count(j, w, -radius, radius)
    return cache, pad, sums, cols, np.zeros((3, w)), np.zeros(w), np.zeros(w)


@njit(**JIT)
def next_moments(state, xp, i, radius, cu2, last):
    """Row ``i + radius`` of the plane ``xp`` into the ring, then row ``i``'s window counts
    (``last``: the row count :func:`window_counts` returned for row ``i - 1``, -1 at row
    0) and moments into ``state`` (:func:`moment_state`). Returns the count of values read
    that are not a finite number ``>= 0`` and the new row count."""
    cache, pad, sums, cols, counts, mu, var = state
    h = xp.shape[0]
    bad = next_row(cache, xp, i, radius)
    last = window_counts(i, h, radius, cols, cu2, last, counts)
    row_moments(cache, pad, sums, i, h, radius, cols, counts[1], mu, var)
    return bad, last


@njit(**JIT)
def row_moments(cache, pad, sums, i, h, radius, cols, inv, mu, var):
    """The window mean ``mu`` (at least 0) and population variance ``var`` (at least 0) of
    every pixel of row ``i`` (of ``h``), its window's rows in the ring ``cache``; ``cols``
    the in-image width of each pixel's window, ``inv = 1 / n``. Near-flat windows are
    summed again as deviations from the pixel (:func:`_centred`)."""
    size = 2 * radius + 1
    w = mu.shape[0]
    c1, c2 = pad[0, radius : radius + w], pad[1, radius : radius + w]
    r = 0
    while r < size:  # rows i - radius .. i + radius, four per pass (zeros outside)
        k = min(4, size - r)
        _down(cache, i - radius + r, size, k, c1, c2, r == 0)
        r += k
    s1, s2 = sums[0], sums[1]
    c = 0
    while c < size:  # then the columns, four per pass
        k = min(4, size - c)
        _across(pad[0], pad[1], c, k, s1, s2, c == 0)
        c += k
    flat = 0
    for j in range(w):
        m1 = s1[j] * inv[j]
        q = s2[j] - s1[j] * m1
        fine = q >= FLAT * s2[j] and s2[j] < np.inf
        v = q * inv[j]
        mu[j] = m1 if m1 > 0.0 else 0.0  # -0.0 cells sum to -0.0
        var[j] = v if fine else -1.0
        flat += not fine
    if flat:
        _near_flat(cache, pad, sums, i, h, radius, cols, mu, var)


@njit(**JIT)
def _near_flat(cache, pad, sums, i, h, radius, cols, mu, var):
    """The moments of row ``i``'s near-flat windows (``var < 0`` on entry): the row's sums
    of deviations from each pixel's own value ``C`` (:func:`centred_sums`, vectorised),
    taken where ``(1 + (C - mean)^2 / var) n <= 2^13`` (the variance then within about
    ``2^13 u = 2^-40`` of its value; ``(C - mean)^2 <= var`` always qualifies); elsewhere
    (a centre far out in a near-flat window) two passes over the pixel's cells
    (:func:`_centred`)."""
    size = 2 * radius + 1
    t1, t2 = sums[2], sums[3]
    centred_sums(cache, i, h, radius, pad, t1, t2)  # pad: zero outside its middle
    centre = cache[i % size]
    first, last = max(i - radius, 0), min(i + radius, h - 1)
    for j in range(mu.shape[0]):
        if var[j] >= 0.0:
            continue
        n = np.float64((last - first + 1) * cols[j])
        m1 = t1[j] / n
        v = (t2[j] - t1[j] * m1) / n
        if m1 * m1 <= max(_SPREAD / n - 1.0, 1.0) * v or (m1 == 0.0 and v == 0.0):
            m = centre[j] + m1
            mu[j], var[j] = (m if m > 0.0 else 0.0), (v if v > 0.0 else 0.0)
        else:
            mu[j], var[j] = _centred(cache, i, j, first, last, radius, cols[j])


@njit(**JIT)
def _centred(cache, i, j, first, last, radius, width):
    """Window mean and variance of pixel ``(i, j)`` from the deviations ``d = x - C`` of
    its cells from its own value ``C`` (the window's rows ``first .. last`` in ``cache``,
    row ``r`` in slot ``r % size``), in two passes: their mean ``m`` first, then the
    squares of ``d - m`` (less the square of their sum, which rounding leaves). Nothing
    cancels but that small correction: the variance is within about ``(n + 3) u`` of its
    value, relative (``u = 2^-53``), whatever the window's mean; equal cells give 0
    exactly; squares beyond float64's range give ``inf``."""
    size, w = cache.shape[0], cache.shape[1]
    c = cache[i % size, j]
    lo, hi = max(j - radius, 0), min(j + radius, w - 1)
    t1 = 0.0
    for r in range(first, last + 1):
        row = cache[r % size]
        for k in range(lo, hi + 1):
            t1 += row[k] - c
    n = np.float64((last - first + 1) * width)
    m = t1 / n
    e1, e2 = 0.0, 0.0
    for r in range(first, last + 1):
        row = cache[r % size]
        for k in range(lo, hi + 1):
            e = (row[k] - c) - m
            e1 += e
            e2 += e * e
    v = (e2 - e1 * (e1 / n)) / n
    mu = c + m
    return (mu if mu > 0.0 else 0.0), (v if v > 0.0 else 0.0)


@njit(**JIT, inline="always")
def ci2_of(mu, var, n):
    """``Ci^2 = var / mu^2``, clamped to ``[0, n - 1]`` (its bound for non-negative data);
    ``0 / 0 = 0``, ``var / 0 = inf`` (clamped). A mean whose square underflows (cells
    below about 1e-154) divides by 0 too and gives ``n - 1``, as in the tensor code."""
    ci2 = var / (mu * mu) if mu > 0.0 else (0.0 if var == 0.0 else np.inf)
    return ci2 if ci2 < n - 1.0 else n - 1.0


@njit(**JIT, inline="always")
def heterogeneity(mu, var, n, cu, cmax, damping):
    """The enhanced filters' ``h = damping (Ci - Cu) / (Cmax - Ci)`` from the window mean
    and variance: 0 at or below ``Cu`` (homogeneous), ``inf`` at or above ``Cmax`` (a
    point target), ``Ci = sqrt(Ci^2)`` with ``Ci^2`` as :func:`ci2_of` gives it over ``n``
    cells. ``Ci`` is formed by the same operations as in the tensor code, so both
    put a pixel in the same class even where ``Ci`` is exactly ``Cu`` or ``Cmax`` (a corner
    pixel's four cells, one bright among zeros, have ``Ci^2 = 3 = Cmax^2`` at one look)."""
    ci = np.sqrt(ci2_of(mu, var, n))
    h = damping * (ci - cu) / (cmax - ci) if cu < ci < cmax else 0.0
    return np.inf if ci >= cmax else h


_DOUBT = 2.0**-40  # relative margin of a class border within which Ci is formed as above
_TINY_MEAN = 2.0**-480  # below it mu^2 may lose precision or underflow (as above: exactly)


@njit(**JIT, inline="always")
def quick_heterogeneity(mu, var, n, cu, cmax, damping):
    """:func:`heterogeneity` with one division and one square root instead of two and
    one: ``h = damping (s - Cu mu) / (Cmax mu - s)`` with ``s = sqrt(var)`` (``Ci = s /
    mu``), and whether the pixel is *doubtful*: within ``2^-40`` (relative) of a class
    border (``Ci`` near ``Cu`` or ``Cmax``), near the clamp of ``Ci^2`` at ``n - 1``, or
    with a mean of 0 or below ``2^-480``. Elsewhere the class is
    :func:`heterogeneity`'s (both ``Ci`` lie within a few ulps of the exact ratio, far
    inside that margin) and ``h`` as accurate as its: a few ulps, more where ``Ci`` nears a
    border and both subtract nearly equal numbers (relative error about ``2^-52 Ci / |Ci -
    border|``, so at most ``2^-11`` for a pixel that is not doubtful). A doubtful pixel is
    to be taken by :func:`heterogeneity` itself (``damping = 0``, say, leaves no weight to
    blur a misplaced class)."""
    s = np.sqrt(var)
    a = s - cu * mu
    b = cmax * mu - s
    h = damping * a / b if a > 0.0 else 0.0
    h = h if b > 0.0 else np.inf
    m2 = mu * mu
    doubt = (
        (abs(a) <= _DOUBT * s)
        | (abs(b) <= _DOUBT * s)
        | (var >= (n - 1.0) * m2 * (1.0 - _DOUBT))
        | (mu < _TINY_MEAN)
    )
    return h, doubt


@njit(**JIT)
def window_counts(i, h, radius, cols, cu2, last, counts):
    """Per pixel of row ``i`` (of ``h``), into the rows of ``counts``: the window's cell
    count ``n``, ``1 / n`` and ``cu2 / (n - 1)`` (``cols``: each column's
    in-image window width), recomputed only when the window's in-image rows differ from
    ``last`` (they do only near the top and bottom); returns the row count."""
    nv = axis_count(i, h, -radius, radius)
    if nv != last:
        for j in range(counts.shape[1]):
            n = nv * cols[j]
            counts[0, j] = n
            counts[1, j] = 1.0 / n
            counts[2, j] = cu2 / (n - 1.0)
    return nv


@njit(**JIT)
def centred_sums(cache, i, h, radius, work, t1, t2):
    """Sums of the deviations ``t1`` and squared deviations ``t2`` of the window cells of
    every pixel of row ``i`` from the pixel's own value (the window rows are in ``cache``,
    row ``r`` in slot ``r % (2 radius + 1)``; ``work`` ``(4, W + 2 radius)`` scratch, zero
    outside its middle ``W`` columns).

    Each column of the window is summed as deviations from its cell in row ``i``, then the
    columns' sums are moved to deviations from the pixel (``sum (x - C)^2 = S2 + d (2 S1 +
    n d)``, ``d`` the column's cell minus ``C``): since ``C`` is a cell of the window,
    ``(C - mean)^2`` is at most ``count`` times the variance and the variance ``(t2 - t1^2
    / n) / n`` loses at most a factor ``count`` of float64 precision (:func:`_near_flat`
    takes it where that factor is small)."""
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


@njit(**JIT, inline="always")
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


@njit(**JIT, inline="always")
def _column(s1, s2, cc, nc, c, w):
    """The four padded rows of :func:`centred_sums` from column ``c``, ``w`` long."""
    return s1[c : c + w], s2[c : c + w], cc[c : c + w], nc[c : c + w]


@njit(**JIT, inline="always")
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
