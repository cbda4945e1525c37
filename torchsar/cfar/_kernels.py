"""numba kernels of the pinwheel-block CFARs' per-pixel rules (GO, SO and VI): from the
window sums to the statistic in one pass, with the values of the tensor code in
:mod:`torchsar.cfar.blocks` and :mod:`torchsar.cfar.vi` bit for bit (the same float64
operations in the same order, elementwise), without its full-size temporaries.

Counts may be geometric ``(1, 1, rr, W)`` planes shared by the batch or ``(B, C, rr, W)``
(with a no-data mask); sums are ``(B, C, rr, W)``; ``shift`` is ``(B, C)``.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = [
    "block_extreme_ratio",
    "counts_present",
    "os_ratio",
    "ring_mean_ratio_masked",
    "vi_rule_ratio",
]

_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}  # x / 0: inf or NaN, as torch

_CA, _GO, _SO, _CA_A, _CA_B = range(5)


@njit(**_JIT, inline="always")
def _mean(s1, count, shift):
    """:meth:`torchsar.windows.Sums.mean` of one cell."""
    if count > 0:
        return s1 / max(count, 1.0) + shift
    return 0.0


@njit(**_JIT, inline="always")
def _ratio(num, den):
    """:func:`torchsar.cfar.core.ratio` of one cell (``0 / 0 = 0``, never NaN; a ``-0.0``
    denominator is zero: ``den + 0.0`` is ``+0.0``)."""
    q = num / (den + 0.0)
    return 0.0 if q != q else q


@njit(**_JIT)
def block_extreme_ratio(x, count, s1, shift, is_max):
    """``x / extreme block mean`` (:func:`torchsar.cfar.blocks.extreme_mean`, then
    :func:`~torchsar.cfar.core.ratio`): ``count`` ``(K, Bc, Cc, rr, W)``, ``s1`` ``(K, B, C,
    rr, W)``; float64 ``(B, C, rr, W)``."""
    k_, b_, c_, rr, w = s1.shape
    out = np.empty((b_, c_, rr, w))
    fill = -np.inf if is_max else np.inf
    for b in range(b_):
        bc = b if count.shape[1] > 1 else 0
        for c in range(c_):
            cc = c if count.shape[2] > 1 else 0
            sh = shift[b, c]
            for i in range(rr):
                for j in range(w):
                    est = fill
                    for k in range(k_):
                        n = count[k, bc, cc, i, j]
                        m = _mean(s1[k, b, c, i, j], n, sh) if n > 0 else fill
                        better = m > est if is_max else m < est
                        est = m if better else est
                    if is_max:
                        est = est if est > 0.0 else 0.0
                    elif est == np.inf or est == -np.inf:
                        est = 0.0
                    out[b, c, i, j] = _ratio(np.float64(x[b, c, i, j]), est)
    return out


@njit(**_JIT, inline="always")
def _variable(n, s1, s2, mean, k_vi):
    """:func:`torchsar.cfar.vi._variable` of one half (``n`` cells, sums ``s1``, ``s2``)."""
    dof = n - 1.0
    m = s1 / max(n, 1.0)
    v = (s2 - m * s1) / max(dof, 1.0)
    var = (v if v > 0.0 else 0.0) if dof > 0 else 0.0
    vi = 1.0 + _ratio(var, mean * mean)
    return vi > k_vi or n <= 1


@njit(**_JIT)
def vi_rule_ratio(x, count, s1, s2, ring_count, ring_s1, shift, k_vi, k_mr, scale):
    """The VI rule and statistic of every pixel (:func:`torchsar.cfar.vi.vi`'s
    ``statistic`` before :func:`~torchsar.cfar.core.finish`): blocks 0, 1 form half A and 2,
    3 half B; ``scale`` ``(5, Sb, Sc, rr, W)`` is ``full / alpha`` of each rule. Returns the
    float64 statistic ``(B, C, rr, W)``."""
    _, b_, c_, rr, w = s1.shape
    out = np.empty((b_, c_, rr, w))
    for b in range(b_):
        bc = b if count.shape[1] > 1 else 0
        rb = b if ring_count.shape[0] > 1 else 0
        sb = b if scale.shape[1] > 1 else 0
        for c in range(c_):
            cc = c if count.shape[2] > 1 else 0
            rc = c if ring_count.shape[1] > 1 else 0
            sc = c if scale.shape[2] > 1 else 0
            sh = shift[b, c]
            for i in range(rr):
                for j in range(w):
                    na = count[0, bc, cc, i, j] + count[1, bc, cc, i, j]
                    nb = count[2, bc, cc, i, j] + count[3, bc, cc, i, j]
                    a1 = s1[0, b, c, i, j] + s1[1, b, c, i, j]
                    b1 = s1[2, b, c, i, j] + s1[3, b, c, i, j]
                    a2 = s2[0, b, c, i, j] + s2[1, b, c, i, j]
                    b2 = s2[2, b, c, i, j] + s2[3, b, c, i, j]
                    ma, mb = _mean(a1, na, sh), _mean(b1, nb, sh)
                    var_a = _variable(na, a1, a2, ma, k_vi)
                    var_b = _variable(nb, b1, b2, mb, k_vi)
                    rule = _GO if (ma > k_mr * mb) or (mb > k_mr * ma) else _CA
                    if var_a and not var_b:
                        rule = _CA_B
                    if var_b and not var_a:
                        rule = _CA_A
                    if var_a and var_b:
                        rule = _SO
                    if na == 0 and nb > 0:
                        rule = _CA_B
                    if nb == 0 and na > 0:
                        rule = _CA_A
                    if rule == _CA:
                        est = _mean(ring_s1[b, c, i, j], ring_count[rb, rc, i, j], sh)
                    elif rule == _GO:
                        est = ma if ma >= mb else mb
                    elif rule == _SO:
                        est = ma if ma <= mb else mb
                    elif rule == _CA_A:
                        est = ma
                    else:
                        est = mb
                    stat = _ratio(np.float64(x[b, c, i, j]), est)
                    out[b, c, i, j] = stat * scale[rule, sb, sc, i, j]
    return out


@njit(**_JIT)
def counts_present(count, size):
    """Which integer counts ``0 .. size - 1`` occur in ``count`` (rounded)."""
    seen = np.zeros(size, np.bool_)
    flat = count.ravel()
    for i in range(flat.size):
        seen[int(np.rint(flat[i]))] = True
    return seen


@njit(**_JIT)
def ring_mean_ratio_masked(x, count, s1, shift, n, scale):
    """CA's statistic over a masked ring (:func:`torchsar.cfar.ca.ring_mean_ratio` with a
    mask): ``x / mean`` with the border rule (``scale[c] = factor(n) / factor(c)`` where the
    count ``c != n``) and ``-inf`` where no cell counted; float64 ``(B, C, rr, W)``."""
    b_, c_, rr, w = s1.shape
    out = np.empty((b_, c_, rr, w))
    for b in range(b_):
        for c in range(c_):
            sh = shift[b, c]
            for i in range(rr):
                for j in range(w):
                    cnt = count[b, c, i, j]
                    if cnt <= 0:
                        out[b, c, i, j] = -np.inf
                        continue
                    stat = _ratio(np.float64(x[b, c, i, j]), s1[b, c, i, j] / max(cnt, 1.0) + sh)
                    if cnt != n:
                        stat = stat * scale[int(np.rint(cnt))]
                    out[b, c, i, j] = stat
    return out


@njit(**_JIT)
def os_ratio(x, est, count, n, scale, out):
    """OS-CFAR's statistic without no-data (:func:`torchsar.cfar.os_cfar.os`'s tensor code
    bit for bit): ``I / x_(k)`` in float64 (``0 / 0 = 0``), times ``scale[c]`` where the
    pixel's ring count ``c`` (``count``, ``(H, W)``, shared by every plane) is not ``n``,
    cast to ``out``'s dtype; ``x``, ``est`` and ``out`` are ``(P, H, W)``."""
    p_, h, w = x.shape
    for p in range(p_):
        for i in range(h):
            for j in range(w):
                stat = _ratio(np.float64(x[p, i, j]), np.float64(est[p, i, j]))
                c = count[i, j]
                if c != n:
                    stat = stat * scale[c]
                out[p, i, j] = stat
