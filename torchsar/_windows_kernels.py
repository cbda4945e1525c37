"""numba kernel of :func:`torchsar.windows.windowed`'s strip sums, with the tensor code's
values bit for bit and without its full-batch float64 temporaries.

For each image plane it builds the strip's zero-bordered float64 buffer of ``x - shift``
(times the valid mask, when there is one), its integral images (running sums along each
row, then down each column, in the order ``cumsum`` adds) and the signed four-corner sums of
every rectangle in the order :func:`torchsar.windows._corner_sum` adds them, so every sum
equals the tensor code's. One plane's buffers (a few hundred kB) stay in cache while all
its sums are read.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["strip_sums"]

_JIT = {"cache": True, "nogil": True}


@njit(**_JIT)
def _integral(buf):
    """Running sums along each row, then down each column (each element gets the same
    additions, in the same order, as ``cumsum`` along the last axis and then the one before;
    the column pass runs row by row so it vectorises across columns)."""
    hb, wb = buf.shape
    for i in range(hb):
        acc = 0.0
        for j in range(wb):
            acc += buf[i, j]
            buf[i, j] = acc
    for i in range(1, hb):
        for j in range(wb):
            buf[i, j] = buf[i - 1, j] + buf[i, j]


@njit(**_JIT)
def _corners(s, rects, q, out):
    """Signed corner sums of region ``q`` of ``rects`` (rows: region, sign, top, bot, left,
    right) from the integral image ``s`` into ``out`` ``(rr, W)``: the first corner is copied
    (or negated), the others added or subtracted in turn, one branch-free pass each."""
    rr, w = out.shape
    first = True
    for k in range(rects.shape[0]):
        if rects[k, 0] != q:
            continue
        sign, top, bot, left, right = (
            rects[k, 1],
            rects[k, 2],
            rects[k, 3],
            rects[k, 4],
            rects[k, 5],
        )
        for corner in range(4):
            if corner == 0:
                sg, r0, c0 = sign, bot, right
            elif corner == 1:
                sg, r0, c0 = -sign, top, right
            elif corner == 2:
                sg, r0, c0 = -sign, bot, left
            else:
                sg, r0, c0 = sign, top, left
            src = s[r0 : r0 + rr, c0 : c0 + w]
            if first:
                if sg > 0:
                    out[:, :] = src
                else:
                    out[:, :] = -src
                first = False
            elif sg > 0:
                for i in range(rr):
                    for j in range(w):
                        out[i, j] = out[i, j] + src[i, j]
            else:
                for i in range(rr):
                    for j in range(w):
                        out[i, j] = out[i, j] - src[i, j]


@njit(**_JIT)
def strip_sums(x, r, rr, pad, shift, vmask, has_mask, moments, rects, n_regions):
    """``(count, s1, s2)`` of every region for output rows ``[r, r + rr)`` of ``x`` ``(B, C,
    H, W)``: arrays ``(n_regions, B, C, rr, W)`` float64 (``count`` only with a mask, ``s2``
    only with ``moments >= 2``; otherwise empty)."""
    b_, c_, h, w = x.shape
    hb, wb = rr + 2 * pad + 1, w + 2 * pad + 1
    lo, hi = max(r - pad, 0), min(r + rr + pad, h)
    n2 = n_regions if moments >= 2 else 0
    nc = n_regions if has_mask else 0
    s1 = np.empty((n_regions, b_, c_, rr, w))
    s2 = np.empty((n2, b_, c_, rr, w))
    cnt = np.empty((nc, b_, c_, rr, w))
    buf = np.empty((hb, wb))
    sq = np.empty((hb, wb))
    vb = np.empty((hb, wb))
    for b in range(b_):
        for c in range(c_):
            buf[:] = 0.0
            vb[:] = 0.0
            sh = shift[b, c]
            for i in range(lo, hi):
                bi = 1 + i - (r - pad)
                for j in range(w):
                    v = np.float64(x[b, c, i, j]) - sh
                    if has_mask:
                        m = 1.0 if vmask[b, c, i, j] else 0.0
                        vb[bi, pad + 1 + j] = m
                        v = v * m
                    buf[bi, pad + 1 + j] = v
            if moments >= 2:
                for i in range(hb):
                    for j in range(wb):
                        sq[i, j] = buf[i, j] * buf[i, j]
                _integral(sq)
            _integral(buf)
            if has_mask:
                _integral(vb)
            for q in range(n_regions):
                _corners(buf, rects, q, s1[q, b, c])
                if moments >= 2:
                    _corners(sq, rects, q, s2[q, b, c])
                if has_mask:
                    _corners(vb, rects, q, cnt[q, b, c])
                    for i in range(rr):
                        for j in range(w):
                            cnt[q, b, c, i, j] = np.round(cnt[q, b, c, i, j])
    return cnt, s1, s2
