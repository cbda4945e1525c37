"""numba kernel of the Frost-type filters in one sweep over the image rows: the window's
coefficient of variation, each pixel's decay, and the mean weighted by ``exp(-decay d)``
over the distance shells of the window (:func:`torchsar.windows.exp_distance_mean`'s
definition), with no full-size temporaries.

Per output row: the window moments of :func:`torchsar._moment_kernels.row_moments`; the
sums ``S_d`` of every distance shell from vertical pair sums ``x[i - p] + x[i + p]`` and
their horizontal pairs (the orbits ``(±p, ±q), (±q, ±p)``); the in-image cell counts
``n_d`` of the shells likewise; then ``(I + sum_d e_d S_d) / (1 + sum_d e_d n_d)`` with
``e_d = exp(-decay d)``, shells in increasing distance. ``exp`` is evaluated by
:func:`torchsar._vector_exp.exp_neg` (vectorisable, with fused multiply-adds). Float64
throughout, cast once.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from torchsar._block_sums import FMA, JIT
from torchsar._moment_kernels import ci2_of, heterogeneity, moment_state, next_moments, prime
from torchsar._vector_exp import exp_neg

__all__ = ["frost_filter"]


@njit(**JIT)
def _pairs(cache, i, h, radius, size, v, vn):
    """Vertical pair sums of row ``i``: ``v[p] = x[i - p] + x[i + p]`` (``x[i]`` for ``p =
    0``; rows outside the image count as absent) into the padded rows of ``v``, and ``vn[p]``
    the number of those rows in the image."""
    w = cache.shape[1]
    for p in range(radius + 1):
        dst = v[p, radius : radius + w]
        up, down = i - p, i + p
        has_up, has_down = 0 <= up < h, p > 0 and 0 <= down < h
        a, b = cache[up % size], cache[down % size]
        if has_up and has_down:
            for j in range(w):
                dst[j] = a[j] + b[j]
        elif has_up or has_down:
            src = a if has_up else b
            for j in range(w):
                dst[j] = src[j]
        else:
            for j in range(w):
                dst[j] = 0.0
        vn[p] = has_up + has_down


@njit(**JIT)
def _shell_counts(shells, vn, hcount, n):
    """``n[shell, j]``: the in-image cells of each distance shell around pixel ``j`` of a
    row whose vertical pairs hold ``vn[p]`` rows, ``hcount[q, j]`` the columns ``j +- q``
    in the image."""
    n[:, :] = 0.0
    w = n.shape[1]
    for o in range(shells.shape[0]):
        sh, p, q = shells[o, 0], shells[o, 1], shells[o, 2]
        cnt = n[sh]
        for j in range(w):
            cnt[j] += vn[p] * hcount[q, j]
        if p != q:
            for j in range(w):
                cnt[j] += vn[q] * hcount[p, j]


@njit(**JIT)
def _orbit_sum(v, p, q, radius, dst, init):
    """``dst (+)=`` the sum over the orbit ``(±p, ±q), (±q, ±p)`` of each pixel from the
    padded vertical pair sums ``v`` (``v[p]`` at columns ``j ± q``, and ``v[q]`` at ``j ±
    p`` unless ``p == q``; an offset of 0 counted once); ``init``: assign instead of add."""
    w = dst.shape[0]
    a, b = v[p], v[q]
    a_lo, a_hi = a[radius - q : radius - q + w], a[radius + q : radius + q + w]
    b_lo, b_hi = b[radius - p : radius - p + w], b[radius + p : radius + p + w]
    one_a, one_b, same = q == 0, p == 0, p == q
    for j in range(w):
        t = a_lo[j] if one_a else a_lo[j] + a_hi[j]
        if not same:
            t = t + (b_lo[j] if one_b else b_lo[j] + b_hi[j])
        dst[j] = t if init else dst[j] + t


@njit(**JIT, inline="always")
def _power(prev, base, out):
    """``out = prev * base`` (the next power of a shell's weight)."""
    for j in range(out.shape[0]):
        out[j] = prev[j] * base[j]


@njit(**FMA, inline="always")
def _accumulate(e, sk, nk, centre, num, den, first):
    """``num += e sk``, ``den += e nk`` (one FMA each), from ``num = centre``, ``den = 1``
    when ``first``."""
    if first:
        for j in range(num.shape[0]):
            num[j] = centre[j] + e[j] * sk[j]
            den[j] = 1.0 + e[j] * nk[j]
    else:
        for j in range(num.shape[0]):
            num[j] += e[j] * sk[j]
            den[j] += e[j] * nk[j]


@njit(**FMA)  # exp_neg's polynomial with FMAs
def frost_filter(x, radius, shells, dist, powers, enhanced, damping, cu2, cmax2, out):
    """A Frost-type filter of every plane of ``x`` ``(P, H, W)`` into ``out``.

    ``shells``: int64 rows ``(shell, p, q)`` of the orbits (``0 <= p <= q <= radius``) of
    every non-zero distance shell, shells numbered ``0..S-1`` in increasing distance
    ``dist[s]``. ``powers``: ``(bases, base_of, multiple)``, each distance as ``multiple
    * bases[base_of]``: one ``exp`` per base, the weight of the ``m``-th multiple as the
    ``m``-th power of the base's (within a few ulps of its own ``exp``; an ``exp`` of its
    own where the multiples skip one). The decay is ``damping Ci^2`` (Frost) or,
    ``enhanced``, ``damping (Ci - Cu) / (Cmax - Ci)`` between ``Cu`` and ``Cmax``, 0 at or
    below ``Cu`` (the window mean), ``inf`` at or above ``Cmax`` (the pixel itself).

    Returns how many values of ``x`` are not a finite number ``>= 0`` (the input check,
    made as the values are read; ``out`` means nothing unless 0)."""
    p_, h, w = x.shape
    size = 2 * radius + 1
    wp = w + 2 * radius
    n_shells = dist.shape[0]
    state = moment_state(radius, w)
    cache, counts, mu, var = state[0], state[4], state[5], state[6]  # cache: row r in r % size
    # horizontal pair counts of every offset b: how many of j - b, j + b are in the image
    hcount = np.zeros((radius + 1, w))
    for b in range(radius + 1):
        for j in range(w):
            hcount[b, j] = 1.0 if b == 0 else (j - b >= 0) + (j + b < w)
    v = np.zeros((radius + 1, wp))
    vn = np.zeros(radius + 1, np.int64)
    last_vn = np.full(radius + 1, -1, np.int64)  # the vn the shells' counts n were made for
    s = np.zeros((n_shells, w))
    n = np.zeros((n_shells, w))
    decay, num, den = np.zeros(w), np.zeros(w), np.zeros(w)
    bases, base_of, multiple = powers
    e_base = np.zeros((bases.shape[0], w))  # exp(-decay * base) of each base
    e_pow = np.zeros((bases.shape[0], w))  # its power at the base's last shell
    last_m = np.zeros(bases.shape[0], np.int64)
    cu, cmax = np.sqrt(cu2), np.sqrt(cmax2)
    bad = 0
    for pl in range(p_):
        xp = x[pl]
        bad += prime(cache, xp, radius)
        last = -1
        for i in range(h):
            b, last = next_moments(state, xp, i, radius, cu2, last)
            bad += b
            centre = cache[i % size]
            if enhanced:
                for j in range(w):
                    decay[j] = heterogeneity(mu[j], var[j], counts[0, j], cu, cmax, damping)
            else:
                for j in range(w):
                    decay[j] = damping * ci2_of(mu[j], var[j], counts[0, j])
            _pairs(cache, i, h, radius, size, v, vn)
            for o in range(shells.shape[0]):  # a shell's orbits are consecutive rows
                sh, p, q = shells[o, 0], shells[o, 1], shells[o, 2]
                _orbit_sum(v, p, q, radius, s[sh], o == 0 or shells[o - 1, 0] != sh)
            if not np.array_equal(vn, last_vn):  # the shells' counts: only near top, bottom
                _shell_counts(shells, vn, hcount, n)
                last_vn[:] = vn
            for b in range(bases.shape[0]):
                db, eb = bases[b], e_base[b]
                for j in range(w):
                    eb[j] = exp_neg(-(decay[j] * db))
                last_m[b] = 0
            for k in range(n_shells):  # nearest shells first
                b, m = base_of[k], multiple[k]
                if m == 1:  # the base's own weight
                    _accumulate(e_base[b], s[k], n[k], centre, num, den, k == 0)
                elif m == last_m[b] + 1:  # the next power of it
                    prev = e_base[b] if last_m[b] == 1 else e_pow[b]
                    _power(prev, e_base[b], e_pow[b])
                    _accumulate(e_pow[b], s[k], n[k], centre, num, den, k == 0)
                else:  # a multiple after a gap: its own exp
                    dk, e = dist[k], e_pow[b]
                    for j in range(w):
                        e[j] = exp_neg(-(decay[j] * dk))
                    _accumulate(e, s[k], n[k], centre, num, den, k == 0)
                last_m[b] = m
            oi = out[pl, i]
            for j in range(w):
                oi[j] = num[j] / den[j]
    return bad
