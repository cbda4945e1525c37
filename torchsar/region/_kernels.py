"""numba kernel of the region-growing CFAR: the whole per-seed loop of one image (steps b–i)
compiled, with the semantics of the Python code in :mod:`~torchsar.region.grow`,
:mod:`~torchsar.region.rings` and :mod:`~torchsar.region.detector`, bit for bit.

- Growth (step c): the first ``n_init`` pixels by rescanning the candidates with the
  running mean, as :func:`~torchsar.region.grow.grow`; then, instead of the heap, the flood
  fixpoint the heap ends with (the argument of :mod:`~torchsar.region.grow`: the region is
  the connected component of the growable pixels with ``|F - mu_N| <= tau * beta`` for its
  final ``beta``), found by a breadth-first flood that retries the pixels it refused
  whenever ``beta`` grows. The same set of pixels, in another order; nothing downstream
  depends on the order.
- Rings (steps e–h): square dilations on the region's crop by running counts (exact), then
  the values of the region and of the censored ring gathered in row-major crop order and
  reduced with numpy's pairwise summation (:func:`np_sum`), so ``mu_T``, ``mu_C`` and
  ``sigma_C`` equal those of ``ndarray`` reductions to the bit.
- Test and bookkeeping (step i): as :func:`~torchsar.region.detector._visit`.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["detect_loop", "np_sum"]

_JIT = {"cache": True, "nogil": True}

# reason codes of the per-region rows (index into torchsar.region.table.REASONS)
ACCEPTED, BELOW_K, FEW_BACKGROUND, TOO_LARGE = 0, 1, 2, 3


@njit(**_JIT)
def _block(a, lo, n):
    """numpy's pairwise summation of a block ``a[lo:lo + n]``, ``n <= 128`` (a plain loop
    below 8, else 8 accumulators combined as a tree, then the rest)."""
    if n < 8:
        res = -0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    m = n - n % 8
    i = 8
    while i < m:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(**_JIT)
def _pairwise(a, n):
    """numpy's ``pairwise_sum`` of ``a[:n]``: blocks of at most 128, larger ranges split in
    halves rounded down to a multiple of 8 and summed left + right. The recursion is
    unrolled with an explicit stack (numba's cache cannot hold a recursive function)."""
    if n <= 128:
        return _block(a, 0, n)
    todo_lo = np.empty(128, dtype=np.int64)  # depth <= log2(n / 128) + 1 < 64 per branch
    todo_n = np.empty(128, dtype=np.int64)
    todo_join = np.empty(128, dtype=np.bool_)
    done = np.empty(128, dtype=np.float64)
    top, nd = 1, 0
    todo_lo[0], todo_n[0], todo_join[0] = 0, n, False
    while top:
        top -= 1
        lo, m, join = todo_lo[top], todo_n[top], todo_join[top]
        if join:  # both halves are done: left + right
            nd -= 1
            done[nd - 1] = done[nd - 1] + done[nd]
        elif m <= 128:
            done[nd] = _block(a, lo, m)
            nd += 1
        else:
            m2 = m // 2
            m2 -= m2 % 8
            todo_lo[top], todo_n[top], todo_join[top] = lo, m, True
            todo_lo[top + 1], todo_n[top + 1], todo_join[top + 1] = lo + m2, m - m2, False
            todo_lo[top + 2], todo_n[top + 2], todo_join[top + 2] = lo, m2, False
            top += 3
    return done[0]


@njit(**_JIT)
def np_sum(a, n):
    """``np.add.reduce(a[:n])`` of a float64 array, to the bit (the reduction starts from
    the identity 0.0)."""
    return 0.0 + _pairwise(a, n)


@njit(**_JIT)
def _grow(f, free, stamp, tag, seed, tau, n_init, offs, region, cand, low):
    """Grow one region from ``seed`` into ``region``; returns its size (the seed first).

    Indices are those of the image padded by one never-free pixel on every side, so a
    neighbour is ``p + offs[t]`` without bounds checks; their order is the image's
    row-major order, so ties by index are broken as in :func:`torchsar.region.grow.grow`.

    The first ``n_init`` pixels as :func:`torchsar.region.grow.grow` (rescanning the
    candidates with the running mean, ties by flat index); then the flood fixpoint that the
    heap ends with: a breadth-first flood adding every neighbour with
    ``|F - mu_N| <= tau * beta`` (``beta`` the running maximum), the pixels it refused
    kept in ``cand`` and retried whenever ``beta`` has grown, until none passes. Pixels with
    ``F < low`` are never queued (the floor; ``-inf``: none)."""
    region[0] = seed
    n = 1
    total = f[seed]
    beta = f[seed]
    stamp[seed] = tag
    nc = 0
    for o in offs:
        q = seed + o
        if free[q] and stamp[q] != tag and f[q] >= low:
            stamp[q] = tag
            cand[nc] = q
            nc += 1
    while n < n_init and nc > 0:  # the reference mean changes: rescan the few candidates
        mu = total / n
        j = 0
        bq = cand[0]
        bk = abs(f[bq] - mu)
        for i in range(1, nc):
            q = cand[i]
            kq = abs(f[q] - mu)
            if kq < bk or (kq == bk and q < bq):
                j, bq, bk = i, q, kq
        if bk > tau * beta:
            return n
        nc -= 1
        cand[j] = cand[nc]
        region[n] = bq
        n += 1
        total += f[bq]
        if f[bq] > beta:
            beta = f[bq]
        for o in offs:
            q = bq + o
            if free[q] and stamp[q] != tag and f[q] >= low:
                stamp[q] = tag
                cand[nc] = q
                nc += 1
    mu_n = total / n
    limit = tau * beta
    head = n  # the pixels before head have had their neighbours queued
    while True:
        kept = 0  # retry the refused pixels with the current limit
        added = n
        for i in range(nc):
            q = cand[i]
            if abs(f[q] - mu_n) <= limit:
                region[n] = q
                n += 1
                if f[q] > beta:
                    beta = f[q]
                    limit = tau * beta
            else:
                cand[kept] = q
                kept += 1
        nc = kept
        if n == added:
            return n
        while head < n:  # flood from the new pixels
            p = region[head]
            head += 1
            for o in offs:
                q = p + o
                if free[q] and stamp[q] != tag and f[q] >= low:
                    stamp[q] = tag
                    if abs(f[q] - mu_n) <= limit:
                        region[n] = q
                        n += 1
                        if f[q] > beta:
                            beta = f[q]
                            limit = tau * beta
                    else:
                        cand[nc] = q
                        nc += 1


@njit(**_JIT)
def _dilate(mask, ch, cw, radius, rows, out, run):
    """Square dilation (side ``2 radius + 1``, outside = False) of the ``(ch, cw)`` crop
    ``mask`` into ``out``: running counts along rows into ``rows``, then along columns."""
    for i in range(ch):
        base = i * cw
        run[0] = 0
        for j in range(cw):
            run[j + 1] = run[j] + mask[base + j]
        for j in range(cw):
            hi = min(cw, j + radius + 1)
            lo = max(0, j - radius)
            rows[base + j] = run[hi] > run[lo]
    for j in range(cw):
        run[0] = 0
        for i in range(ch):
            run[i + 1] = run[i] + rows[i * cw + j]
        for i in range(ch):
            hi = min(ch, i + radius + 1)
            lo = max(0, i - radius)
            out[i * cw + j] = run[hi] > run[lo]


@njit(**_JIT)
def _ring_stats(region, n, w, h, guard, background, raw, target, low, taken, ws, vals):
    """Steps d–h for the region ``region[:n]`` (padded indices, see :func:`_grow`; ``taken``
    padded too, the images not): ``(mu_t, n_background, mu_c, sigma_c)``, as
    :func:`torchsar.region.rings.ring_stats` (the same values, to the bit)."""
    mask, kk, dd, rows, run = ws
    w2 = w + 2
    pad = guard + background
    rmin, rmax, cmin, cmax = h, -1, w, -1
    for t in range(n):
        r, c = divmod(region[t], w2)
        rmin = min(rmin, r - 1)
        rmax = max(rmax, r - 1)
        cmin = min(cmin, c - 1)
        cmax = max(cmax, c - 1)
    r0, r1 = max(rmin - pad, 0), min(rmax + pad + 1, h)
    c0, c1 = max(cmin - pad, 0), min(cmax + pad + 1, w)
    ch, cw = r1 - r0, c1 - c0
    mask[: ch * cw] = 0
    for t in range(n):
        r, c = divmod(region[t], w2)
        mask[(r - 1 - r0) * cw + (c - 1 - c0)] = 1
    _dilate(mask, ch, cw, guard, rows, kk, run)
    _dilate(mask, ch, cw, pad, rows, dd, run)
    m = 0
    for i in range(ch):
        for j in range(cw):
            if mask[i * cw + j]:
                vals[m] = target[(r0 + i) * w + c0 + j]
                m += 1
    mu_t = np_sum(vals, m) / m
    m = 0
    for i in range(ch):
        for j in range(cw):
            a = i * cw + j
            p = (r0 + i) * w + c0 + j
            if dd[a] and not kk[a] and low[p] < mu_t and not taken[(r0 + i + 1) * w2 + c0 + j + 1]:
                vals[m] = raw[p]
                m += 1
    if m == 0:
        return mu_t, 0, np.nan, np.nan
    mu_c = np_sum(vals, m) / m
    for i in range(m):
        d = vals[i] - mu_c
        vals[i] = d * d
    return mu_t, m, mu_c, math.sqrt(np_sum(vals, m) / m)


@njit(**_JIT)
def _statistic(mu_t, mu_c, sigma_c):
    diff = mu_t - mu_c
    if sigma_c > 0:
        return diff / sigma_c
    return math.copysign(math.inf, diff) if diff != 0.0 else 0.0  # NaN too, as Python's


@njit(**_JIT)
def detect_loop(
    f,
    raw,
    target,
    low,
    h,
    w,
    seeds,
    tau,
    n_init,
    guard,
    background,
    k,
    min_background,
    conn,
    blocking_all,
    max_size,
    max_fraction,
    floor,
):
    """Visit the seeds of one image (flat float64 planes ``(h * w,)``), brightest first.

    ``max_size < 0`` and ``max_fraction < 0`` mean no limit; ``floor`` 0 means none.
    Returns the painted statistic and region ids ``(h * w,)`` and the per-region columns
    (seed index, size, ``mu_t``, ``mu_c``, ``sigma_c``, background size, statistic,
    accepted, reason code).
    """
    npx = h * w
    w2 = w + 2
    n2 = (h + 2) * w2
    fp = np.zeros(n2)  # F on the padded grid; the border is never free
    free = np.zeros(n2, dtype=np.uint8)
    for r in range(h):
        fp[(r + 1) * w2 + 1 : (r + 1) * w2 + 1 + w] = f[r * w : (r + 1) * w]
        free[(r + 1) * w2 + 1 : (r + 1) * w2 + 1 + w] = 1
    if conn == 8:
        offs = np.array([-w2, w2, -1, 1, -w2 - 1, -w2 + 1, w2 - 1, w2 + 1], dtype=np.int32)
    else:
        offs = np.array([-w2, w2, -1, 1], dtype=np.int32)
    stamp = np.zeros(n2, dtype=np.int32)
    covered = np.zeros(n2, dtype=np.bool_)
    taken = np.zeros(n2, dtype=np.bool_)
    stat = np.full(n2, -np.inf)
    region_id = np.zeros(n2, dtype=np.int32)
    region = np.empty(npx, dtype=np.int32)
    cand = np.empty(npx, dtype=np.int32)
    vals = np.empty(npx, dtype=np.float64)
    ws = (
        np.empty(npx, dtype=np.uint8),
        np.empty(npx, dtype=np.uint8),
        np.empty(npx, dtype=np.uint8),
        np.empty(npx, dtype=np.uint8),
        np.empty(max(h, w) + 1, dtype=np.int64),
    )
    ns = seeds.size
    r_seed = np.empty(ns, dtype=np.int64)
    r_size = np.empty(ns, dtype=np.int64)
    r_mu_t = np.empty(ns)
    r_mu_c = np.empty(ns)
    r_sigma = np.empty(ns)
    r_nbg = np.empty(ns, dtype=np.int64)
    r_stat = np.empty(ns)
    r_ok = np.empty(ns, dtype=np.bool_)
    r_reason = np.empty(ns, dtype=np.int8)
    nreg = 0
    for s in seeds:
        sp = s + 2 * (s // w) + w2 + 1  # padded index
        if covered[sp]:
            continue
        tag = nreg + 1
        lowest = floor * fp[sp] if floor > 0 else -np.inf
        n = _grow(fp, free, stamp, tag, sp, tau, n_init, offs, region, cand, lowest)
        for t in range(n):
            covered[region[t]] = True
            if blocking_all:
                free[region[t]] = 0
        mu_t, mu_c, sigma_c, nbg = np.nan, np.nan, np.nan, 0
        z, ok = -np.inf, False
        if (max_size >= 0 and n > max_size) or (max_fraction >= 0 and n > max_fraction * npx):
            reason = TOO_LARGE
        else:
            mu_t, nbg, mu_c, sigma_c = _ring_stats(
                region, n, w, h, guard, background, raw, target, low, taken, ws, vals
            )
            if nbg < min_background:
                reason = FEW_BACKGROUND
            else:
                z = _statistic(mu_t, mu_c, sigma_c)
                ok = z > k
                reason = ACCEPTED if ok else BELOW_K
        if ok:
            for t in range(n):
                taken[region[t]] = True
                free[region[t]] = 0
        for t in range(n):
            q = region[t]
            if stat[q] < z:
                stat[q] = z
                region_id[q] = tag
        r_seed[nreg] = s
        r_size[nreg] = n
        r_mu_t[nreg] = mu_t
        r_mu_c[nreg] = mu_c
        r_sigma[nreg] = sigma_c
        r_nbg[nreg] = nbg
        r_stat[nreg] = z
        r_ok[nreg] = ok
        r_reason[nreg] = reason
        nreg += 1
    out_stat = np.empty(npx)
    out_id = np.empty(npx, dtype=np.int32)
    for r in range(h):
        out_stat[r * w : (r + 1) * w] = stat[(r + 1) * w2 + 1 : (r + 1) * w2 + 1 + w]
        out_id[r * w : (r + 1) * w] = region_id[(r + 1) * w2 + 1 : (r + 1) * w2 + 1 + w]
    return (
        out_stat,
        out_id,
        r_seed[:nreg],
        r_size[:nreg],
        r_mu_t[:nreg],
        r_mu_c[:nreg],
        r_sigma[:nreg],
        r_nbg[:nreg],
        r_stat[:nreg],
        r_ok[:nreg],
        r_reason[:nreg],
    )


@njit(inline="always", **_JIT)
def _root(parent, p):
    """The root of ``p`` in the union-find forest ``parent`` (path halving)."""
    while parent[p] != p:
        parent[p] = parent[parent[p]]
        p = parent[p]
    return p


@njit(inline="always", **_JIT)
def _union(parent, p, q):
    """Join the trees of ``p`` and ``q``; the smaller root (the earlier pixel) stays root."""
    a, b = _root(parent, p), _root(parent, q)
    if a < b:
        parent[b] = a
    elif b < a:
        parent[a] = b


@njit(**_JIT)
def _components(mask, h, w, conn8, lab, parent):
    """Label the 4- or 8-connected components of the flat ``(h * w,)`` bool ``mask`` into
    ``lab`` (0 elsewhere), numbered in raster order of each component's first pixel (as
    :func:`scipy.ndimage.label` numbers them); returns their count.

    One raster pass joins every pixel with its earlier neighbours in a union-find forest
    whose roots are the components' first pixels, skipping the joins already made (with
    8-connectivity the pixel above is joined with those beside it; with 4-connectivity the
    pixels above and to the left are joined when the one above-left is set). Every parent
    is an earlier pixel, so a second raster pass gives each pixel its parent's number (a new
    one at a root)."""
    for r in range(h):
        for c in range(w):
            p = r * w + c
            if not mask[p]:
                continue
            left = c > 0 and mask[p - 1]
            up = r > 0 and mask[p - w]
            if up:
                parent[p] = _root(parent, p - w)
                if left and not conn8 and not mask[p - w - 1]:
                    _union(parent, p, p - 1)
                continue
            parent[p] = _root(parent, p - 1) if left else p
            if conn8 and r > 0:
                if not left and c > 0 and mask[p - w - 1]:
                    parent[p] = _root(parent, p - w - 1)
                if c < w - 1 and mask[p - w + 1]:
                    _union(parent, p, p - w + 1)
    n = 0
    for p in range(h * w):
        if not mask[p]:
            lab[p] = 0
        elif parent[p] == p:
            n += 1
            lab[p] = n
        else:
            lab[p] = lab[parent[p]]
    return n


@njit(**_JIT)
def fill_holes(stat, region_id, h, w, k, row_stat):
    """:func:`torchsar.region.detector._fill_holes` on the flat painted ``stat`` and
    ``region_id`` (in place): every 4-connected component of the pixels with ``stat <= k``
    that does not reach the image border takes the largest id of an accepted pixel in the
    3x3 neighbourhoods of its pixels, and that region's statistic ``row_stat[id - 1]``.

    Worked on the accepted pixels' bounding box padded by one unaccepted pixel, whose
    component is everything reaching the box's outside."""
    r0, r1, c0, c1 = _box(stat > k, h, w, 0)
    if r1 == 0:
        return
    bh, bw = r1 - r0 + 2, c1 - c0 + 2
    free = np.ones(bh * bw, dtype=np.bool_)  # unaccepted cells of the padded box
    for i in range(1, bh - 1):
        for j in range(1, bw - 1):
            free[i * bw + j] = not stat[(r0 + i - 1) * w + c0 + j - 1] > k
    lab = np.empty(bh * bw, dtype=np.int64)
    n = _components(free, bh, bw, False, lab, np.empty(bh * bw, dtype=np.int64))
    owner = np.zeros(n + 1, dtype=np.int64)
    for i in range(1, bh - 1):
        for j in range(1, bw - 1):
            m = lab[i * bw + j]
            if m == 0 or m == lab[0]:
                continue
            for ii in range(i - 1, i + 2):  # a hole cell is >= 2 cells from the box's edge
                for jj in range(j - 1, j + 2):
                    q = (r0 + ii - 1) * w + c0 + jj - 1
                    if not free[ii * bw + jj] and region_id[q] > owner[m]:
                        owner[m] = region_id[q]
    for i in range(1, bh - 1):
        for j in range(1, bw - 1):
            m = lab[i * bw + j]
            if m != 0 and m != lab[0]:
                q = (r0 + i - 1) * w + c0 + j - 1
                region_id[q] = owner[m]
                stat[q] = row_stat[owner[m] - 1]


@njit(**_JIT)
def _box(mask, h, w, margin):
    """The bounding box ``(r0, r1, c0, c1)`` (end-exclusive) of the flat ``mask`` widened by
    ``margin`` and clipped to the image; ``r1 == 0`` when the mask is empty."""
    r0, r1, c0, c1 = h, -1, w, -1
    for r in range(h):
        for c in range(w):
            if mask[r * w + c]:
                r0, r1 = min(r0, r), r
                c0, c1 = min(c0, c), max(c1, c)
    if r1 < 0:
        return 0, 0, 0, 0
    r0, c0 = max(r0 - margin, 0), max(c0 - margin, 0)
    return r0, min(r1 + margin + 1, h), c0, min(c1 + margin + 1, w)


@njit(**_JIT)
def _cut(mask, w, box):
    """The flat copy of the box ``(r0, r1, c0, c1)`` of the flat ``mask``."""
    r0, r1, c0, c1 = box
    bw = c1 - c0
    out = np.empty((r1 - r0) * bw, dtype=mask.dtype)
    for i in range(r1 - r0):
        for j in range(bw):
            out[i * bw + j] = mask[(r0 + i) * w + c0 + j]
    return out


@njit(**_JIT)
def drop_small_objects(stat, region_id, h, w, k, min_size, n_rows):
    """:func:`torchsar.region.detector._drop_small_objects` on the flat painted ``stat``
    (in place): the pixels of 8-connected components of ``stat > k`` smaller than
    ``min_size`` get ``-inf``; returns, per region id ``0..n_rows``, whether it lost pixels."""
    dropped = np.zeros(n_rows + 1, dtype=np.bool_)
    mask = stat > k
    box = _box(mask, h, w, 0)
    r0, r1, c0, c1 = box
    if r1 == 0:
        return dropped
    bh, bw = r1 - r0, c1 - c0
    lab = np.empty(bh * bw, dtype=np.int64)
    n = _components(_cut(mask, w, box), bh, bw, True, lab, np.empty(bh * bw, dtype=np.int64))
    size = np.zeros(n + 1, dtype=np.int64)
    for a in range(bh * bw):
        size[lab[a]] += 1
    for a in range(bh * bw):
        if lab[a] and size[lab[a]] < min_size:
            q = (r0 + a // bw) * w + c0 + a % bw
            stat[q] = -np.inf
            dropped[region_id[q]] = True
    return dropped


@njit(**_JIT)
def merged_labels(mask, h, w, merge):
    """One label per group of ``mask`` pixels closer than ``merge`` (0: 8-connected),
    numbered in raster order of each group's first pixel: the 8-connected components of the
    mask dilated by a ``(2 merge + 1)^2`` square, kept on the mask (flat int64). Worked on
    the mask's box widened by ``merge`` (raster order is the same there)."""
    out = np.zeros(h * w, dtype=np.int64)
    box = _box(mask, h, w, merge)
    r0, r1, c0, c1 = box
    if r1 == 0:
        return out
    bh, bw = r1 - r0, c1 - c0
    m = _cut(mask, w, box)
    grown = m.copy()
    if merge > 0:
        g = np.empty(bh * bw, dtype=np.uint8)
        run = np.empty(max(bh, bw) + 1, dtype=np.int64)
        _dilate(m.view(np.uint8), bh, bw, merge, np.empty(bh * bw, dtype=np.uint8), g, run)
        grown = g.view(np.bool_)
    lab = np.empty(bh * bw, dtype=np.int64)
    _components(grown, bh, bw, True, lab, np.empty(bh * bw, dtype=np.int64))
    for a in range(bh * bw):
        if m[a]:
            out[(r0 + a // bw) * w + c0 + a % bw] = lab[a]
    return out


@njit(**_JIT)
def seeds(f, h, w, window):
    """Steps a–b on the flat float64 ``(h * w,)`` image F: the flat indices of the pixels
    equal to the maximum of their ``window x window`` neighbourhood (cells outside the
    image not counted), brightest first, ties by index: ``seed_order(f, local_maxima(f))``
    of :mod:`torchsar.region.seeds`."""
    r = window // 2
    rows = f.copy()  # running maximum along rows, then along columns: shifted whole lines
    for i in range(h):
        line = f[i * w : (i + 1) * w]
        out = rows[i * w : (i + 1) * w]
        for d in range(1, r + 1):
            for j in range(w - d):
                a, b = line[j + d], line[j]
                out[j] = a if a > out[j] else out[j]
                out[j + d] = b if b > out[j + d] else out[j + d]
    peak = rows.copy()
    for d in range(1, r + 1):
        for i in range(h - d):
            for j in range(w):
                a, b = rows[(i + d) * w + j], rows[i * w + j]
                q, q2 = i * w + j, (i + d) * w + j
                peak[q] = a if a > peak[q] else peak[q]
                peak[q2] = b if b > peak[q2] else peak[q2]
    idx = np.empty(h * w, dtype=np.int64)
    n = 0
    for q in range(h * w):
        if f[q] == peak[q]:
            idx[n] = q
            n += 1
    idx = idx[:n]
    return idx[np.argsort(-f[idx], kind="mergesort")]
