"""numba kernels of the window CFARs' per-pixel rules over :func:`torchsar.windows.windowed`'s
sums (VI with no-data, OS-CFAR's ratio and decision): from the window
sums to the statistic in one pass, with the values of the tensor code in
:mod:`torchsar.cfar.vi` and :mod:`torchsar.cfar.os_cfar` bit for bit (the same float64
operations in the same order, elementwise), without its full-size temporaries. Without
no-data the CPU takes the one-sweep kernels instead (:mod:`torchsar._box_kernels`,
:mod:`torchsar._pinwheel_kernels`); :func:`censor_mean` is AC's global pre-threshold.

Counts may be geometric ``(1, 1, rr, W)`` planes shared by the batch or ``(B, C, rr, W)``
(with a no-data mask); sums are ``(B, C, rr, W)``; ``shift`` is ``(B, C, rr, W)`` (each
pixel's, or the image's value broadcast).

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from torchsar._pinwheel_kernels import ratio_of as _ratio
from torchsar._pinwheel_kernels import vi_rule

__all__ = [
    "censor_mean",
    "half_maps",
    "os_decision",
    "os_ratio",
    "pending_halves",
    "vi_rule_ratio",
]

_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}  # x / 0: inf or NaN, as torch


@njit(**_JIT)
def vi_rule_ratio(x, count, s1, s2, shift, k_vi, k_mr, scale):
    """The VI rule and statistic of every pixel (:func:`torchsar.cfar.vi.vi`'s
    ``statistic`` before :func:`~torchsar.cfar.core.finish`): blocks 0, 1 form half A and 2,
    3 half B, the two halves the ring; ``scale`` ``(5, Sb, Sc, rr, W)`` is ``full / alpha``
    of each rule. Returns the float64 statistic ``(B, C, rr, W)``."""
    _, b_, c_, rr, w = s1.shape
    out = np.empty((b_, c_, rr, w))
    for b in range(b_):
        bc = b if count.shape[1] > 1 else 0
        sb = b if scale.shape[1] > 1 else 0
        for c in range(c_):
            cc = c if count.shape[2] > 1 else 0
            sc = c if scale.shape[2] > 1 else 0
            for i in range(rr):
                for j in range(w):
                    na = count[0, bc, cc, i, j] + count[1, bc, cc, i, j]
                    nb = count[2, bc, cc, i, j] + count[3, bc, cc, i, j]
                    a1 = s1[0, b, c, i, j] + s1[1, b, c, i, j]
                    b1 = s1[2, b, c, i, j] + s1[3, b, c, i, j]
                    a2 = s2[0, b, c, i, j] + s2[1, b, c, i, j]
                    b2 = s2[2, b, c, i, j] + s2[3, b, c, i, j]
                    halves = (na, nb, a1, b1, a2, b2)
                    v = np.float64(x[b, c, i, j])
                    sh = shift[b, c, i, j]
                    rule, stat = vi_rule(v, halves, a1 + b1, na + nb, sh, k_vi, k_mr)
                    out[b, c, i, j] = stat * scale[rule, sb, sc, i, j]
    return out


@njit(**_JIT)
def os_ratio(x, est, count, n, scale, out):
    """OS-CFAR's statistic (:func:`torchsar.cfar.os_cfar.os`'s tensor code bit for bit):
    ``I / x_(k)`` in float64 (``0 / 0 = 0``), times ``scale[c]`` where the pixel's ring
    count ``c`` (``count`` ``(Pc, H, W)``: one plane shared by every image plane without
    no-data, or one per plane) is not ``n``, ``-inf`` where it is 0 (no counted cell),
    cast to ``out``'s dtype; ``x``, ``est`` and ``out`` are ``(P, H, W)``."""
    p_, h, w = x.shape
    for p in range(p_):
        cp = count[p if count.shape[0] > 1 else 0]
        for i in range(h):
            for j in range(w):
                stat = _ratio(np.float64(x[p, i, j]), np.float64(est[p, i, j]))
                c = cp[i, j]
                if c == 0:
                    stat = -np.inf
                elif c != n:
                    stat = stat * scale[c]
                out[p, i, j] = stat


@njit(**_JIT, inline="always")
def _os_passes(i_val, c, s, thr):
    """Whether a ring order statistic ``c`` (float32) makes the pixel ``i_val`` a
    detection: :func:`os_ratio`'s statistic ``f32((I / c) * s) > thr``."""
    q = _ratio(i_val, np.float64(c))
    return np.float32(q * s) > thr


@njit(**_JIT)
def _os_cutoff_search(i_val, s, thr, cell):
    """The largest float32 ``c >= 0`` with :func:`_os_passes` (``+inf`` if every value
    passes) and whether any does, by bisection on the bit patterns of non-negative float32
    values (``cell``: a float32 array of one element, ``cell.view(int32)`` its bits)."""
    bits = cell.view(np.int32)
    cell[0] = np.float32(0.0)
    if not _os_passes(i_val, cell[0], s, thr):
        return np.float32(0.0), False
    cell[0] = np.float32(np.inf)
    if _os_passes(i_val, cell[0], s, thr):
        return cell[0], True
    lo, hi = 0, 0x7F800000  # passes at lo, not at hi
    while hi - lo > 1:
        mid = lo + (hi - lo) // 2
        bits[0] = mid
        if _os_passes(i_val, cell[0], s, thr):
            lo = mid
        else:
            hi = mid
    bits[0] = lo
    return cell[0], True


@njit(**_JIT, inline="always")
def _os_cutoff_near(i_val, s, thr, guess, cell):
    """:func:`_os_cutoff_search` from a positive finite ``guess`` (the rounded ``I s /
    thr``, within an ulp or two of the answer): the boundary found among the two float32
    values on each side of it, else by the bisection."""
    bits = cell.view(np.int32)
    cell[0] = guess
    start = bits[0]
    bits[0] = start - 2
    passes = _os_passes(i_val, cell[0], s, thr)
    if passes:  # passes two below the guess: look up to two above
        for k in range(-1, 3):
            bits[0] = start + k
            if not _os_passes(i_val, cell[0], s, thr):
                bits[0] = start + k - 1
                return cell[0], True
    return _os_cutoff_search(i_val, s, thr, cell)


@njit(**_JIT)
def os_decision(x, radius, guard, count, rank, scale, thr, out):
    """OS-CFAR's mask without no-data and without the order statistic (float32 ``x`` ``(P,
    H, W)`` into bool ``out``): the statistic is non-increasing in the ring's order
    statistic, so the values that would pass are a prefix of the sorted ring, and the pixel
    is a detection iff at least ``rank[i, j]`` ring values lie at or below the largest
    float32 ``c`` that passes. ``c`` is found among the two float32 values on each side of
    the rounded ``I s / thr`` (up to five evaluations), else by bisection; then the ring is
    counted in vectorised passes along the row (a pixel without ring cells, rank 0, is
    never detected). The same mask as
    :func:`os_ratio`'s statistic over ``thr``, exactly. ``count``, ``rank``: the pixel's
    in-image ring cells and its rank ``(H, W)``; ``scale[c]`` the border factor (1 at the
    interior count)."""
    p_, h, w = x.shape
    thr = np.float32(thr)  # the threshold as the float32 statistic meets it
    size = 2 * radius + 1
    pad = np.full((h + 2 * radius, w + 2 * radius), np.inf, dtype=np.float32)
    cut = np.empty(w, dtype=np.float32)
    anyone = np.empty(w, dtype=np.bool_)
    every = np.empty(w, dtype=np.bool_)
    below = np.empty(w, dtype=np.int32)
    cell = np.empty(1, dtype=np.float32)
    t64 = np.float64(thr)
    fast = thr > 0.0 and thr < np.inf
    for p in range(p_):
        pad[radius : radius + h, radius : radius + w] = x[p]
        for i in range(h):
            for j in range(w):
                iv = np.float64(x[p, i, j])
                s = scale[count[i, j]]
                c = np.float32(iv * s / t64) if fast else np.float32(0.0)
                if fast and 0.0 < c < np.inf:
                    cut[j], anyone[j] = _os_cutoff_near(iv, s, thr, c, cell)
                else:
                    cut[j], anyone[j] = _os_cutoff_search(iv, s, thr, cell)
                every[j] = cut[j] == np.inf  # every value passes, the padding too
            below[:] = 0
            for a in range(size):
                row = pad[i + a]
                band = a < radius - guard or a > radius + guard
                for b in range(size):
                    if band or b < radius - guard or b > radius + guard:
                        seg = row[b : b + w]
                        for j in range(w):
                            below[j] += seg[j] <= cut[j]
            for j in range(w):
                got = count[i, j] if every[j] else below[j]
                out[p, i, j] = anyone[j] and rank[i, j] > 0 and got >= rank[i, j]


@njit(**_JIT, inline="always")
def _kept_sum(flat, limit):
    """The sum and count of the values of ``flat`` at or below ``limit``: eight running
    sums (each over every eighth value, then added pairwise), so the loop is not one
    chain of dependent additions; the order is fixed by the positions alone."""
    acc = np.zeros(8)
    cnt = np.zeros(8, np.int64)
    n = flat.size - flat.size % 8
    for i in range(0, n, 8):
        for k in range(8):
            v = np.float64(flat[i + k])
            kept = v <= limit
            acc[k] += v if kept else 0.0
            cnt[k] += kept
    for i in range(n, flat.size):
        v = np.float64(flat[i])
        kept = v <= limit
        acc[i - n] += v if kept else 0.0
        cnt[i - n] += kept
    total = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]))
    return total, cnt.sum()


@njit(**_JIT)
def censor_mean(planes, q, ratio_kept, iterations):
    """AC-CFAR's global clutter mean of every plane of ``planes`` ``(P, N)``: the mean, then
    ``iterations`` times the mean of the values at or below ``mu q`` divided by
    ``ratio_kept`` (:func:`torchsar.cfar.ac.global_censor_threshold`'s rule), one pass
    each. Returns float64 ``(P,)``."""
    out = np.empty(planes.shape[0])
    for p in range(planes.shape[0]):
        flat = planes[p]
        total, count = _kept_sum(flat, np.inf)
        mu = total / max(count, 1)
        for _ in range(iterations):
            total, count = _kept_sum(flat, mu * q)
            mu = total / max(count, 1) / ratio_kept
        out[p] = mu
    return out


@njit(**_JIT)
def pending_halves(a, b, half, tables):
    """The distinct ``(rule, a, b)`` whose entry of the factor ``tables`` ``(5, S, S)`` is
    missing (NaN), at the pixels (flat ``a``, ``b``: the two halves' sizes) where a half
    is not whole (``!= half``), each once, in pixel order."""
    seen = np.zeros(tables.shape, np.bool_)
    out = np.empty((min(5 * a.shape[0], tables.size), 3), np.int64)
    m = 0
    for k in range(a.shape[0]):
        p, q = a[k], b[k]
        if p == half and q == half:
            continue
        for r in range(5):
            if tables[r, p, q] != tables[r, p, q] and not seen[r, p, q]:
                seen[r, p, q] = True
                out[m, 0], out[m, 1], out[m, 2] = r, p, q
                m += 1
    return out[:m]


@njit(**_JIT)
def half_maps(a, b, half, tables, inner, full, out):
    """``out[r, k]``: ``full / alpha_r`` at pixel ``k`` for each rule ``r`` (``out`` ``(5,
    N)``): ``inner[r]`` where both halves are whole, else ``full (1 / tables[r, a, b])``
    (times the reciprocal, as torch divides a number by a tensor)."""
    for k in range(a.shape[0]):
        p, q = a[k], b[k]
        whole = p == half and q == half
        for r in range(5):
            out[r, k] = inner[r] if whole else full * (1.0 / tables[r, p, q])
