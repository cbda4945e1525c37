"""numba kernels of the discrimination stage: the binary closing by a disk and the labelling
of connected components, with the results of the numpy / scikit-image code in
:mod:`~torchsar.objects.discriminate` and :mod:`~torchsar.objects.components`, bit for bit.

- Closing: a pixel of a plane is set when it is set in the mask or when every pixel of the
  disk around it is in the mask's dilation by the same disk (zero outside the plane). This
  is :func:`~torchsar.objects.discriminate._close` (zero-padded dilation, erosion as the
  complement of the dilated complement): the padding by the radius keeps every disk around
  an image pixel inside the padded plane, where the padded dilation is the true one.
- Labels: two-pass union-find over each plane in raster order (4 or 8 neighbours, no
  connection across planes), then labels numbered by the raster order of each component's
  first pixel, planes in order: the numbering of
  :func:`~torchsar.objects.components.label_components`. The second pass also lists the
  labelled pixels (flat index into the stack, ascending, and label), which the measurement
  reads instead of searching the label map again.
- Measurements: one pass over the labelled pixels gathers each object's area, plane, box
  and the sums of its rows, columns and their squares and products, as int64, with its
  peak score: :func:`~torchsar.objects.properties.measure_pixels`' reductions. The sums
  are exact integers (as numpy's float64 sums of the same integers are, below ``2^53``,
  in any order), so the moments formed from them are the same floats, bit for bit.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["close_disk", "label_planes", "measure_sums"]

_JIT = {"cache": True, "nogil": True}


@njit(**_JIT)
def _coords(idx, h, w):
    """Plane, row and column ``(3, m)`` of each flat index ``idx`` (``>= 0``) into an
    ``(N, H, W)`` stack: an ascending list is walked row by row without a division (which
    costs more than the rest of a pixel's work); a step back or a jump of many rows
    divides."""
    out = np.empty((3, idx.size), np.int64)
    p, i, start = 0, 0, 0  # plane, row and flat index of the current row's first pixel
    for k in range(idx.size):
        q = idx[k]
        if q < start or q - start >= 8 * w:
            p, rest = divmod(q, h * w)
            i = rest // w
            start = q - rest % w
        while q - start >= w:
            start += w
            i += 1
            if i == h:
                p, i = p + 1, 0
        out[0, k], out[1, k], out[2, k] = p, i, q - start
    return out


@njit(**_JIT)
def _close(idx, n_planes, h, w, dy, dx, r):
    hp, wp = h + 2 * r, w + 2 * r
    grown = np.zeros(n_planes * hp * wp, np.uint8)  # bit 1: in the dilation, bit 2: tested
    base = np.empty(idx.size, np.int64)
    at_ = _coords(idx, h, w)
    for k in range(idx.size):
        p, i, j = at_[0, k], at_[1, k], at_[2, k]
        base[k] = (p * hp + i + r) * wp + j + r
        for o in range(dy.size):
            grown[base[k] + dy[o] * wp + dx[o]] |= 1
    for k in range(idx.size):
        grown[base[k]] |= 2  # in the mask: in the closing
    added = np.empty(idx.size * dy.size, np.int64)
    n_added = 0
    for k in range(idx.size):
        i, j = at_[1, k], at_[2, k]
        for o in range(dy.size):  # the closing lies in the dilation: near a mask pixel
            i2, j2 = i + dy[o], j + dx[o]
            at = base[k] + dy[o] * wp + dx[o]
            if i2 < 0 or i2 >= h or j2 < 0 or j2 >= w or grown[at] & 2:
                continue
            grown[at] |= 2
            full = True
            for o2 in range(dy.size):
                if grown[at + dy[o2] * wp + dx[o2]] & 1 == 0:
                    full = False
                    break
            if full:
                added[n_added] = idx[k] + dy[o] * w + dx[o]
                n_added += 1
    extra = np.sort(added[:n_added])  # few, next to the mask's: merged, not sorted again
    return _merge(idx, extra)


@njit(**_JIT)
def _merge(a, b):
    """The ascending union of the disjoint ascending arrays ``a`` and ``b``."""
    out = np.empty(a.size + b.size, np.int64)
    i = j = 0
    for k in range(out.size):
        if j == b.size or (i < a.size and a[i] < b[j]):
            out[k] = a[i]
            i += 1
        else:
            out[k] = b[j]
            j += 1
    return out


def close_disk(idx: np.ndarray, shape: tuple[int, int, int], radius: int) -> np.ndarray:
    """The set pixels (flat indices, ascending) of the binary closing of the stack ``shape``
    ``(N, H, W)`` whose set pixels are ``idx`` (ascending) by the digital disk of ``radius``
    (``dy^2 + dx^2 <= radius^2``), extensive also at the border (module docstring)."""
    span = np.arange(-radius, radius + 1)
    dy, dx = np.meshgrid(span, span, indexing="ij")
    disk = dy * dy + dx * dx <= radius * radius
    n, h, w = shape
    return _close(
        np.ascontiguousarray(idx, dtype=np.int64),
        n,
        h,
        w,
        dy[disk].astype(np.int64),
        dx[disk].astype(np.int64),
        int(radius),
    )


@njit(**_JIT)
def _find(parent, x):
    root = x
    while parent[root] != root:
        root = parent[root]
    while parent[x] != root:  # path compression
        parent[x], x = root, parent[x]
    return root


@njit(**_JIT)
def _join(parent, a, b):
    """Union of the sets of provisional labels ``a`` and ``b``; returns the new root."""
    ra, rb = _find(parent, a), _find(parent, b)
    if ra < rb:
        parent[rb] = ra
        return ra
    parent[ra] = rb
    return rb


@njit(**_JIT)
def _label(idx, n_planes, h, w, eight):
    labels = np.zeros(n_planes * h * w, np.int32)
    parent = np.zeros(idx.size + 1, np.int32)
    n_prov = 0
    at_ = _coords(idx, h, w)
    for k in range(idx.size):
        q = idx[k]
        i, j = at_[1, k], at_[2, k]
        best = 0
        for di, dj in ((0, -1), (-1, -1), (-1, 0), (-1, 1)):
            if (not eight and di != 0 and dj != 0) or i + di < 0 or not 0 <= j + dj < w:
                continue
            lab = labels[q + di * w + dj]
            if lab != 0:
                best = _find(parent, lab) if best == 0 else _join(parent, best, lab)
        if best == 0:
            n_prov += 1
            parent[n_prov] = n_prov
            best = n_prov
        labels[q] = best
    final = np.zeros(n_prov + 1, np.int32)
    lab_of = np.empty(idx.size, np.int64)
    n = 0
    for k in range(idx.size):
        root = _find(parent, labels[idx[k]])
        if final[root] == 0:
            n += 1
            final[root] = n
        labels[idx[k]] = final[root]
        lab_of[k] = final[root]
    return labels, n, lab_of


def label_planes(
    idx: np.ndarray, shape: tuple[int, int, int], connectivity: int
) -> tuple[np.ndarray, int, np.ndarray]:
    """Connected components of the stack ``shape`` ``(N, H, W)`` whose set pixels are
    ``idx`` (flat, ascending; ``connectivity`` 1: 4-connected, 2: 8-connected):
    ``(labels, n, lab)``, the int32 label stack (``1..n``, unique across planes) and the
    label of each pixel of ``idx``."""
    n_planes, h, w = shape
    labels, n, lab = _label(
        np.ascontiguousarray(idx, dtype=np.int64), n_planes, h, w, connectivity == 2
    )
    return labels.reshape(shape), int(n), lab


@njit(**_JIT)
def _measure(lab, idx, h, w, n, values):
    plane = np.full(n, np.iinfo(np.int64).max, np.int64)
    lo = np.full((2, n), np.iinfo(np.int64).max, np.int64)  # first row, column
    hi = np.full((2, n), -1, np.int64)  # last row, column
    sums = np.zeros((6, n), np.int64)  # area, rows, columns, rows^2, columns^2, products
    peak = np.full(n, -np.inf)
    at_ = _coords(idx, h, w)
    for k in range(lab.size):
        o = lab[k] - 1
        p, i, j = at_[0, k], at_[1, k], at_[2, k]
        plane[o] = min(plane[o], p)
        lo[0, o], hi[0, o] = min(lo[0, o], i), max(hi[0, o], i)
        lo[1, o], hi[1, o] = min(lo[1, o], j), max(hi[1, o], j)
        sums[0, o] += 1
        sums[1, o] += i
        sums[2, o] += j
        sums[3, o] += i * i
        sums[4, o] += j * j
        sums[5, o] += i * j
        v = values[k]
        if v >= peak[o]:  # the last of equal values, as numpy's maximum keeps
            peak[o] = v
    return plane, lo, hi, sums, peak


def measure_sums(
    lab: np.ndarray, idx: np.ndarray, hw: tuple[int, int], n: int, values: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Per object ``1..n`` of the pixels ``idx`` (flat into an ``(N, H, W)`` stack, object
    ``lab``, score ``values``): its plane (lowest), first and last row and column
    (``(2, n)`` each; ``int64`` max and -1 for an object without pixels), the int64 sums
    ``(6, n)`` of 1, row, column, row^2, column^2 and row x column, and its peak score
    (``-inf`` without pixels)."""
    h, w = hw
    return _measure(
        np.ascontiguousarray(lab, dtype=np.int64),
        np.ascontiguousarray(idx, dtype=np.int64),
        int(h),
        int(w),
        int(n),
        np.ascontiguousarray(values, dtype=np.float64),
    )
