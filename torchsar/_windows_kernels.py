"""numba kernels of :func:`torchsar.windows.windowed`'s strip sums, without its full-batch
float64 temporaries.

- :func:`direct_sums` (rectangles and rings, every shape the detectors use): every window
  cell added on its own in float64 as its deviation from the pixel's first in-image
  (valid) cell, in the order of the GPU's kernel (:func:`torchsar._gpu_kernels.region_sums`:
  rectangle by rectangle, each row by row), so the same values bit for bit. The cells are
  added four at a time along the row for every pixel of it (the sums kept in a register
  across the four, one after the other: vectorised across pixels, the order per pixel
  unchanged); the valid cells' counts come from an integral image of the mask (exact
  integers).
- :func:`strip_sums` (any region): for each image plane the strip's zero-bordered float64
  buffer of ``x - shift`` (times the valid mask, when there is one), its integral images
  (running sums along each row, then down each column, in the order ``cumsum`` adds) and
  the signed four-corner sums of every rectangle in the order
  :func:`torchsar.windows._corner_sum` adds them, so every sum equals the tensor code's.
  One plane's buffers (a few hundred kB) stay in cache while all its sums are read.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["direct_sums", "strip_sums", "valid_counts"]

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


@njit(**_JIT)
def _first_cells(xp, has_valid, nxt, lo, i, rects, out):
    """The shift of every pixel of row ``i``: the value (float64) of the first in-image
    cell (valid cell, ``has_valid``) of the rectangles ``rects`` (rows ``(r0, r1, c0,
    c1)`` of offsets, inclusive), in the order the sums add them (rectangle by rectangle,
    each row by row); 0 where none is. ``nxt[r - lo, j]``: the first valid column at or
    after ``j`` in image row ``r`` (``W`` where none is), so each rectangle row is one
    look-up."""
    h, w = xp.shape
    for j in range(w):
        c = 0.0
        found = False
        for t in range(rects.shape[0]):
            top, bot = max(i + rects[t, 0], 0), min(i + rects[t, 1], h - 1)
            left, right = max(j + rects[t, 2], 0), min(j + rects[t, 3], w - 1)
            if left > right:
                continue
            for ii in range(top, bot + 1):
                jj = nxt[ii - lo, left] if has_valid else left
                if jj <= right:
                    c, found = np.float64(xp[ii, jj]), True
                    break
            if found:
                break
        out[j] = c


@njit(**_JIT)
def _next_valid(vp, lo, nxt):
    """``nxt[r, j]``: the first column at or after ``j`` where row ``lo + r`` of ``vp`` is
    non-zero (``W`` where none is)."""
    w = vp.shape[1]
    for r in range(nxt.shape[0]):
        nxt[r, w] = w
        for j in range(w - 1, -1, -1):
            nxt[r, j] = j if vp[lo + r, j] != 0 else nxt[r, j + 1]


@njit(**_JIT)
def _add_cells(row, ok, col, k, shift, o1, o2, moments):
    """Add the ``k <= 4`` cells at columns ``j + col .. j + col + k - 1`` of the padded
    float64 ``row`` to the sums of every pixel ``j`` of an output row, one cell after the
    other as deviations from ``shift[j]``, times the cell's ``ok`` (1.0, or 0.0 for an
    invalid cell or one outside the image, whose value in ``row`` is 0: a term ``+-0.0``,
    which changes no sum, none being ``-0.0``). Four cells in one pass (the sums held in a
    register across them), fewer one per pass; no branch in the loops, so they vectorise
    across pixels. ``o1``, ``o2``: the row's sums of deviations and (``moments >= 2``) of
    their squares."""
    w = shift.shape[0]
    if k < 4:
        for c in range(col, col + k):
            v, m = row[c : c + w], ok[c : c + w]
            if moments >= 2:
                for j in range(w):
                    d = (v[j] - shift[j]) * m[j]
                    o1[j] += d
                    o2[j] += d * d
            else:
                for j in range(w):
                    o1[j] += (v[j] - shift[j]) * m[j]
        return
    seg, m = row[col : col + w + 3], ok[col : col + w + 3]
    if moments >= 2:
        for j in range(w):
            d0 = (seg[j] - shift[j]) * m[j]
            d1 = (seg[j + 1] - shift[j]) * m[j + 1]
            d2 = (seg[j + 2] - shift[j]) * m[j + 2]
            d3 = (seg[j + 3] - shift[j]) * m[j + 3]
            t = o1[j]
            t += d0
            t += d1
            t += d2
            t += d3
            o1[j] = t
            u = o2[j]
            u += d0 * d0
            u += d1 * d1
            u += d2 * d2
            u += d3 * d3
            o2[j] = u
    else:
        for j in range(w):
            t = o1[j]
            t += (seg[j] - shift[j]) * m[j]
            t += (seg[j + 1] - shift[j]) * m[j + 1]
            t += (seg[j + 2] - shift[j]) * m[j + 2]
            t += (seg[j + 3] - shift[j]) * m[j + 3]
            o1[j] = t


@njit(**_JIT)
def _padded_rows(xp, vp, has_valid, lo, hi, pad, rows, ok):
    """Image rows ``lo .. hi - 1`` into ``rows`` in float64, ``pad`` zero columns before
    each, with their cells' weights in ``ok`` (1.0 for a valid cell in the image, else 0.0
    and the value 0)."""
    w = xp.shape[1]
    rows[:] = 0.0
    ok[:] = 0.0
    for i in range(lo, hi):
        for j in range(w):
            good = not has_valid or vp[i, j] != 0
            rows[i - lo, pad + j] = np.float64(xp[i, j]) if good else 0.0
            ok[i - lo, pad + j] = 1.0 if good else 0.0


@njit(**_JIT)
def _count_table(vp, lo, table):
    """``table[i, j]``: how many cells of ``vp[lo : lo + i, :j]`` are non-zero (exact
    integers; ``table`` has a row per image row read, and one more)."""
    w = vp.shape[1]
    for i in range(table.shape[0] - 1):
        run = 0
        for j in range(w):
            run += vp[lo + i, j] != 0
            table[i + 1, j + 1] = table[i, j + 1] + run


@njit(**_JIT)
def _count_rect(table, lo, h, i, rect, out):
    """``out[j] +=`` the valid cells of ``rect`` (offsets ``(r0, r1, c0, c1)``) around pixel
    ``(i, j)`` inside the image (``h`` rows), from :func:`_count_table`'s ``table`` of the
    rows from ``lo``: a difference of four corners, the columns whose rectangle lies inside
    the image in one vectorised pass, the others clamped."""
    w = table.shape[1] - 1
    top, bot = min(max(i + rect[0], 0), h), min(max(i + rect[1] + 1, 0), h)
    if bot <= top:
        return
    up, down = table[top - lo], table[bot - lo]
    a, b = min(max(-rect[2], 0), w), max(min(w - rect[3] - 1, w), 0)  # inside: a <= j < b
    b = max(a, b)
    if b > a:
        d_lo, u_lo = down[a + rect[2] : b + rect[2]], up[a + rect[2] : b + rect[2]]
        d_hi, u_hi = down[a + rect[3] + 1 : b + rect[3] + 1], up[a + rect[3] + 1 : b + rect[3] + 1]
        o = out[a:b]
        for j in range(b - a):
            o[j] += (d_hi[j] - u_hi[j]) - (d_lo[j] - u_lo[j])
    for lo_j, hi_j in ((0, a), (b, w)):
        for j in range(lo_j, hi_j):
            left, right = min(max(j + rect[2], 0), w), min(max(j + rect[3] + 1, 0), w)
            right = max(right, left)
            out[j] += (down[right] - up[right]) - (down[left] - up[left])


@njit(**_JIT)
def direct_sums(x, valid, has_valid, rects, starts, r, rr, moments):
    """The window sums of :func:`torchsar._gpu_kernels.region_sums` on the CPU, bit for bit:
    for output rows ``[r, r + rr)`` of every plane of ``x`` ``(P, H, W)`` and every region
    (the rectangles ``rects[starts[q]:starts[q + 1]]``, rows ``(r0, r1, c0, c1)`` of
    offsets, inclusive, disjoint), ``sum(x - shift)`` and ``sum((x - shift)^2)`` over its
    in-image cells (only the valid ones, ``valid`` uint8 ``(P, H, W)``, where
    ``has_valid``, also counted), each cell added on its own in float64 in the kernel's
    order (rectangle by rectangle, each row by row), ``shift`` the pixel's first in-image
    (valid) cell in that order. No integral image, so nothing cancels.

    Returns ``s1``, ``s2`` (empty unless ``moments >= 2``) and ``count`` (empty unless
    ``has_valid``) ``(K, P, rr, W)`` and ``shift`` ``(P, rr, W)``, float64."""
    p_, h, w = x.shape
    k_ = starts.shape[0] - 1
    s1 = np.zeros((k_, p_, rr, w))
    s2 = np.zeros((k_ if moments >= 2 else 0, p_, rr, w))
    cnt = np.zeros((k_ if has_valid else 0, p_, rr, w))
    shift = np.empty((p_, rr, w))
    pad, up, down = 0, 0, 0
    for t in range(rects.shape[0]):
        pad = max(pad, abs(rects[t, 2]), abs(rects[t, 3]))
        up, down = min(up, rects[t, 0]), max(down, rects[t, 1])
    lo, hi = min(max(r + up, 0), h), max(min(r + rr + down, h), 0)  # the rows read
    lo = min(lo, hi)
    rows = np.zeros((hi - lo, w + 2 * pad + 3))
    ok = np.zeros((hi - lo, w + 2 * pad + 3))
    read = hi - lo if has_valid else 0  # the mask's tables: with a mask only
    table = np.zeros((read + 1, w + 1), np.int64)  # the valid cells' integral image
    nxt = np.zeros((read, w + 1), np.int64)  # each row's next valid column
    for p in range(p_):
        xp, vp = x[p], valid[p if has_valid else 0]
        _padded_rows(xp, vp, has_valid, lo, hi, pad, rows, ok)
        if has_valid:
            _count_table(vp, lo, table)
            _next_valid(vp, lo, nxt)
        for k in range(rr):
            i = r + k
            sh = shift[p, k]
            _first_cells(xp, has_valid, nxt, lo, i, rects[: starts[k_]], sh)
            for q in range(k_):
                o1 = s1[q, p, k]
                o2 = s2[q, p, k] if moments >= 2 else o1
                for t in range(starts[q], starts[q + 1]):
                    if has_valid:
                        _count_rect(table, lo, h, i, rects[t], cnt[q, p, k])
                    for a in range(rects[t, 0], rects[t, 1] + 1):
                        if not 0 <= i + a < h:
                            continue
                        b = rects[t, 2]
                        while b <= rects[t, 3]:  # four cells per pass, in order
                            n = min(4, rects[t, 3] - b + 1)
                            row, weights = rows[i + a - lo], ok[i + a - lo]
                            _add_cells(row, weights, pad + b, n, sh, o1, o2, moments)
                            b += n
    return s1, s2, shift, cnt


@njit(**_JIT)
def valid_counts(valid, rects):
    """How many valid cells (``valid`` uint8 ``(P, H, W)``, non-zero) of the rectangles
    ``rects`` (rows ``(r0, r1, c0, c1)`` of offsets, inclusive, disjoint) lie in the image
    around every pixel: float64 ``(P, H, W)``, exact (from an integral image of the mask)."""
    p_, h, w = valid.shape
    out = np.zeros((p_, h, w))
    table = np.zeros((h + 1, w + 1), np.int64)
    for p in range(p_):
        _count_table(valid[p], 0, table)
        for i in range(h):
            for t in range(rects.shape[0]):
                _count_rect(table, 0, h, i, rects[t], out[p, i])
    return out
