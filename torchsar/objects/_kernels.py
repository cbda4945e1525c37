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

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["close_disk", "label_planes"]

_JIT = {"cache": True, "nogil": True}


@njit(**_JIT)
def _close(idx, n_planes, h, w, dy, dx, r):
    hp, wp = h + 2 * r, w + 2 * r
    grown = np.zeros(n_planes * hp * wp, np.uint8)  # bit 1: in the dilation, bit 2: tested
    base = np.empty(idx.size, np.int64)
    for k in range(idx.size):
        p, rest = divmod(idx[k], h * w)
        i, j = divmod(rest, w)
        base[k] = (p * hp + i + r) * wp + j + r
        for o in range(dy.size):
            grown[base[k] + dy[o] * wp + dx[o]] |= 1
    for k in range(idx.size):
        grown[base[k]] |= 2  # in the mask: in the closing
    added = np.empty(idx.size * dy.size, np.int64)
    n_added = 0
    for k in range(idx.size):
        rest = idx[k] % (h * w)
        i, j = divmod(rest, w)
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
                added[n_added] = idx[k] - rest + i2 * w + j2
                n_added += 1
    out = np.concatenate((idx, added[:n_added]))
    out.sort()
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
    for k in range(idx.size):
        q = idx[k]
        i, j = divmod(q % (h * w), w)
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
