"""Step c: grow one region from a seed on the despeckled image (the CPU heap).

The paper grows region T from the seed by always adding the boundary pixel most similar to
the region, accepting it while ``psi = |F(p) - mu_N| / beta <= tau``, where ``mu_N`` is the
mean of the first ``N`` pixels added and ``beta`` the maximum of F over T. An optional floor
(not in the paper) keeps every pixel with ``F < floor * F(seed)`` out of the region, in each
phase below: such pixels are treated as not growable for this region.

Implementation: flat (row-major) pixel indices, the image as a flat float64 memoryview (fast
scalar access to Python floats), a ``bytearray`` of growable pixels shared by every region
of the image, and an integer stamp array so nothing is cleared between regions. Until ``N``
pixels are in T the reference mean changes with every addition, so the few candidates are
rescanned; after that the key ``|F(p) - mu_N|`` of a pixel never changes and a binary heap
(``heapq``) orders the boundary. Since ``beta`` only grows and the heap top has the smallest
key, growth stops exactly when the heap top fails the test. Ties are broken by the smaller
flat index, so the result is deterministic.

Large regions (clutter floods, big targets) would make the pure-Python heap the bottleneck,
so after ``budget`` pixels the growth is finished by compiled flood fills on a crop
(:func:`scipy.ndimage.label`, or :func:`skimage.segmentation.flood` on large crops). This is
exact, not an approximation: the region the heap ends with is the connected component,
containing the region so far, of the growable pixels with ``|F - mu_N| <= tau * beta`` for
its final ``beta``, and iterating "flood with ``tau * beta``, update ``beta`` to the maximum
of F over the flood" from any partial heap region converges to that same component (``beta``
only grows, every flood is contained in the final region). Only the order in which pixels
join is lost, and nothing downstream depends on it. The same argument allows two shortcuts:
a flood that reaches an inner crop edge hands its pixels and their maximum to the next,
larger crop at once; and when ``beta`` grows, the previous flood is first extended by a few
one-pixel dilations inside the new tolerance (once that stops changing it is the new
component), the crop being labelled afresh only if it is still growing.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, MutableSequence, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from skimage.segmentation import flood

from torchsar.region.boxes import index_box

__all__ = ["Grid", "grow"]


@dataclass
class Grid:
    """Per-image state shared by every region grown on that image.

    Attributes:
        f: the despeckled image, flattened row-major: a float64 buffer whose items read as
            Python floats (a memoryview of the array: no per-pixel conversion up front).
        width: image width W (rows are ``len(f) // width``).
        free: 1 where a region may grow into the pixel, 0 where it is taken.
        stamp: per-pixel id of the last region that queued the pixel.
        connectivity: 4 (the paper's eq. 4) or 8.
    """

    f: Sequence[float]
    width: int
    free: bytearray
    stamp: MutableSequence[int]
    connectivity: int = 4
    f2d: np.ndarray | None = None

    @staticmethod
    def new(f: np.ndarray, connectivity: int = 4) -> Grid:
        """The state of a fresh image: ``f`` is the ``(H, W)`` float64 despeckled image."""
        f = np.ascontiguousarray(f, dtype=np.float64)
        n = f.size
        flat = memoryview(f.reshape(-1))
        return Grid(flat, f.shape[1], bytearray(b"\x01") * n, [0] * n, connectivity, f)

    @property
    def shape(self) -> tuple[int, int]:
        return (len(self.f) // self.width, self.width)

    def free2d(self) -> np.ndarray:
        """The ``free`` flags as an ``(H, W)`` uint8 array sharing memory."""
        return np.frombuffer(self.free, dtype=np.uint8).reshape(self.shape)

    def neighbours(self) -> Callable[[int], list[int]]:
        """A function returning the in-image 4- or 8-neighbours of a flat index."""
        w, n = self.width, len(self.f)

        def four(p: int) -> list[int]:
            col = p % w
            if 0 < col < w - 1 and w <= p < n - w:  # inside: all four, in the order below
                return [p - w, p + w, p - 1, p + 1]
            out = []
            if p >= w:
                out.append(p - w)
            if p + w < n:
                out.append(p + w)
            if col:
                out.append(p - 1)
            if col + 1 < w:
                out.append(p + 1)
            return out

        def eight(p: int) -> list[int]:
            col = p % w
            out = four(p)
            for q in (p - w, p + w):
                if 0 <= q < n:
                    if col:
                        out.append(q - 1)
                    if col + 1 < w:
                        out.append(q + 1)
            return out

        return four if self.connectivity == 4 else eight


def _first_n(
    grid: Grid,
    seed: int,
    tag: int,
    tau: float,
    n_init: int,
    nbrs: Callable[[int], list[int]],
    low: float,
) -> tuple[list[int], list[int], float, float, bool]:
    """Grow the first ``n_init`` pixels with the running mean as reference (pixels with
    ``F < low`` are never queued).

    Returns the region, the queued candidates, the sum of F over the region (added in the
    order of joining), ``beta`` and whether growth may continue.
    """
    f, free, stamp = grid.f, grid.free, grid.stamp
    region, total, beta = [seed], f[seed], f[seed]
    stamp[seed] = tag
    cand: list[int] = []
    _queue(seed, cand, nbrs, free, stamp, tag, f, low)
    while len(region) < n_init and cand:
        mu = total / len(region)
        j = min(range(len(cand)), key=lambda i: (abs(f[cand[i]] - mu), cand[i]))
        p = cand[j]
        if abs(f[p] - mu) > tau * beta:
            return region, cand, total, beta, False
        cand.pop(j)
        region.append(p)
        total += f[p]
        beta = max(beta, f[p])
        _queue(p, cand, nbrs, free, stamp, tag, f, low)
    return region, cand, total, beta, True


def _queue(
    p: int,
    out: list[int],
    nbrs: Callable[[int], list[int]],
    free: bytearray,
    stamp: MutableSequence[int],
    tag: int,
    f: Sequence[float],
    low: float,
) -> None:
    """Append the growable (free, ``F >= low``), not yet queued neighbours of ``p`` to
    ``out``."""
    for q in nbrs(p):
        if free[q] and stamp[q] != tag and f[q] >= low:
            stamp[q] = tag
            out.append(q)


DEFAULT_BUDGET = 64  # heap pixels before the flood fill: the one default of every caller


def grow(
    grid: Grid,
    seed: int,
    tag: int,
    *,
    tau: float,
    n_init: int,
    budget: int | None = DEFAULT_BUDGET,
    floor: float = 0.0,
) -> np.ndarray:
    """Grow one region from ``seed`` (seed step c).

    Args:
        grid: the image state; pixels with ``grid.free == 0`` are never entered (the seed is
            taken even so). ``grid.stamp`` is updated with ``tag``.
        seed: flat index of the seed.
        tag: a stamp unique to this region (> every earlier tag on this grid).
        tau: similarity tolerance.
        n_init: N, the number of first pixels whose mean is the reference ``mu_N``.
        budget: pixels grown by the Python heap before the flood fill finishes the region
            (None: heap only, pixels in order of joining).
        floor: pixels with ``F < floor * F(seed)`` never join (0: no floor).

    Returns:
        int64 flat indices of the region, the seed first.

    Examples:
        >>> g = Grid.new(np.array([[9.0, 8.0], [1.0, 8.5]]))
        >>> grow(g, 0, 1, tau=0.3, n_init=2).tolist()
        [0, 1, 3]
    """
    f = grid.f
    nbrs = grid.neighbours()
    low = floor * f[seed] if floor > 0 else -math.inf
    region, cand, total, beta, go_on = _first_n(grid, seed, tag, tau, n_init, nbrs, low)
    if not go_on:
        return np.asarray(region, dtype=np.int64)
    mu_n = total / len(region)  # a plain running sum (the compiled kernel's, bit for bit)
    heap = [(abs(f[q] - mu_n), q) for q in cand]
    heapq.heapify(heap)
    limit = tau * beta
    free, stamp = grid.free, grid.stamp
    push, pop = heapq.heappush, heapq.heappop
    cap = len(f) + 1 if budget is None else budget
    while heap and heap[0][0] <= limit:
        p = pop(heap)[1]
        region.append(p)
        fp = f[p]
        if fp > beta:
            beta = fp
            limit = tau * beta
        if len(region) >= cap:
            return _flood_rest(grid, np.asarray(region, dtype=np.int64), mu_n, beta, tau, low)
        for q in nbrs(p):
            if free[q] and stamp[q] != tag and f[q] >= low:
                stamp[q] = tag
                push(heap, (abs(f[q] - mu_n), q))
    return np.asarray(region, dtype=np.int64)


_LABEL_MAX = 1 << 16  # crops up to this many pixels: scipy labelling beats flood's overhead
_MARGIN = 16  # first crop on a large image: the partial region's box widened by this much
_STEPS = 8  # dilations tried before labelling afresh when the tolerance widens
_STRUCTURE = {
    4: ndimage.generate_binary_structure(2, 1),
    8: ndimage.generate_binary_structure(2, 2),
}


def _component(
    dist: np.ndarray, ok: np.ndarray, seed: tuple[int, int], tol: float, connectivity: int
) -> np.ndarray:
    """The connected component of ``ok = dist <= tol`` containing ``seed`` (bool mask)."""
    if dist.size <= _LABEL_MAX:
        lab, _ = ndimage.label(ok, structure=_STRUCTURE[connectivity])
        return lab == lab[seed]
    return flood(dist, seed, tolerance=tol, connectivity=1 if connectivity == 4 else 2)


def _dilate_once(m: np.ndarray, width: int, connectivity: int) -> np.ndarray:
    """A flat row-major mask of rows ``width`` long whose last column is always False,
    dilated by one pixel (4-neighbours, or the 3x3 square for 8): shifts by one along the
    flat array then only leak into that column, so every shift is one contiguous pass."""
    g = m.copy()
    g[width:] |= m[:-width]
    g[:-width] |= m[width:]
    src = g.copy() if connectivity == 8 else m  # 8: widen the column-dilated mask
    g[1:] |= src[:-1]
    g[:-1] |= src[1:]
    return g


def _extend(m: np.ndarray, ok: np.ndarray, connectivity: int, steps: int) -> np.ndarray | None:
    """The component of ``ok`` containing the connected ``(h, w + 1)`` mask ``m``, found by
    up to ``steps`` one-pixel dilations kept inside ``ok`` (both False in the last column,
    ``m`` a subset of ``ok``), or None if the mask was still growing."""
    flat, ok_flat, width = m.reshape(-1), ok.reshape(-1), m.shape[1]
    n = np.count_nonzero(flat)
    for _ in range(steps):
        flat = _dilate_once(flat, width, connectivity)
        flat &= ok_flat
        n_g = np.count_nonzero(flat)  # the dilation contains m: equal counts, equal masks
        if n_g == n:
            return flat.reshape(m.shape)
        n = n_g
    return None


def _touches_edge(m: np.ndarray, box: tuple[int, int, int, int], shape: tuple[int, int]) -> bool:
    """Whether crop mask ``m`` reaches a side of its crop ``box`` that is inside the image
    (beyond which the component may continue)."""
    r0, r1, c0, c1 = box
    h, w = shape
    return bool(
        (r0 > 0 and m[0].any())
        or (r1 < h and m[-1].any())
        or (c0 > 0 and m[:, 0].any())
        or (c1 < w and m[:, -1].any())
    )


def _flood_crop(
    grid: Grid,
    idx: np.ndarray,
    box: tuple[int, int, int, int],
    mu_n: float,
    beta: float,
    tau: float,
    low: float,
) -> tuple[np.ndarray, float, bool]:
    """Iterate flood fills on one crop until ``beta`` is stable or the flood reaches an inner
    crop edge; return the flat indices of the flood, ``beta`` and whether it reached such an
    edge.

    The crop carries one extra, never growable column (for :func:`_extend`). When ``beta``
    grows, the flood so far is first extended by a few dilations; only if it is still
    growing is the crop labelled afresh."""
    r0, r1, c0, c1 = box
    w = grid.width
    f = np.full((r1 - r0, c1 - c0 + 1), -np.inf)
    f[:, :-1] = grid.f2d[r0:r1, c0:c1]
    dist = np.abs(f - mu_n)  # inf in the extra column
    dist[:, :-1][grid.free2d()[r0:r1, c0:c1] == 0] = np.inf
    dist[f < low] = np.inf  # below the floor (the extra column is inf already)
    rows, cols = idx // w - r0, idx % w - c0
    dist[rows, cols] = 0.0
    m = None
    while True:
        ok = dist <= tau * beta
        m = None if m is None else _extend(m, ok, grid.connectivity, _STEPS)
        if m is None:
            m = _component(dist, ok, (int(rows[0]), int(cols[0])), tau * beta, grid.connectivity)
        top = float(f[m].max())
        edge = _touches_edge(m[:, :-1], box, grid.shape)
        if edge or top <= beta:
            break
        beta = top
    p = np.flatnonzero(m)
    width = m.shape[1]
    return p + (p // width) * (w - width) + (r0 * w + c0), top if edge else beta, edge


def _flood_rest(
    grid: Grid, idx: np.ndarray, mu_n: float, beta: float, tau: float, low: float
) -> np.ndarray:
    """Finish a region from its partial heap region ``idx`` with flood fills on a crop around
    it; when the flood reaches a crop edge inside the image, the flood so far (contained in
    the final region, its maximum a valid ``beta``) becomes the new partial region and the
    margin doubles. An image small enough for one labelling is flooded whole: growing crops
    there costs more than it saves."""
    h, w = grid.shape
    seed = idx[0]
    margin = _MARGIN if h * w > _LABEL_MAX else max(h, w)
    while True:
        box = index_box(idx, (h, w), margin)
        flat, beta, edge = _flood_crop(grid, idx, box, mu_n, beta, tau, low)
        idx = np.concatenate([idx[:1], flat[flat != seed]])
        if not edge:
            return idx
        margin *= 2
