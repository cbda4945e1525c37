"""Region-growing CFAR (seed paper section 3, steps a–j).

Pipeline: despeckle and 5x5 local-maximum seeds (tensors, by the caller for the whole
batch), then per image: for each seed, brightest first, skipping seeds already inside a
grown region: grow T on the despeckled image F (CPU heap, :mod:`torchsar.region.grow`) →
guard area K and background ring C by dilation on a crop → censor C → ``mu_C``, ``sigma_C``
on the unfiltered image → accept T iff ``(mu_T - mu_C) / sigma_C > k``.

Two paths compute the same result bit for bit (statistic, labels, table): the Python one
below, and, when numba is installed (:mod:`torchsar._jit`), one compiled loop per image
(:mod:`torchsar.region._kernels`) with compiled hole filling, object sizes and labels.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage
from torch import Tensor

from torchsar import _jit
from torchsar.region.boxes import mask_box
from torchsar.region.grow import Grid, grow
from torchsar.region.params import RegionParams
from torchsar.region.rings import crop_around, ring_stats
from torchsar.region.seeds import local_maxima, seed_order
from torchsar.region.table import REASONS, RegionRow, RegionTable

__all__ = ["detect_image"]


class _ImageState:
    """The per-pixel results of one image while its seeds are visited, and its table."""

    def __init__(self, f: Tensor, p: RegionParams) -> None:
        h, w = f.shape
        self.shape = (h, w)
        self.stat = np.full(h * w, -np.inf)
        self.region_id = np.zeros(h * w, dtype=np.int32)
        self.table = RegionTable()
        self.k = p.k


class _Growth:
    """The Python path's growth state of one image: the grid (free flags, stamps) and which
    pixels are covered by a region or taken by a target."""

    def __init__(self, f: np.ndarray, p: RegionParams) -> None:
        h, w = f.shape
        self.grid = Grid.new(f, p.connectivity)
        self.free = np.frombuffer(self.grid.free, dtype=np.uint8)
        self.covered = np.zeros(h * w, dtype=bool)
        self.taken = np.zeros((h, w), dtype=bool)


def _statistic(mu_t: float, mu_c: float, sigma_c: float) -> float:
    """``(mu_t - mu_c) / sigma_c``; a zero ``sigma_c`` gives ``±inf`` by the sign (0 if equal)."""
    diff = mu_t - mu_c
    if sigma_c > 0:
        return diff / sigma_c
    return math.copysign(math.inf, diff) if diff else 0.0


def _too_large(size: int, image_area: int, p: RegionParams) -> bool:
    """A flood: more than ``max_size`` pixels, or more than ``max_fraction`` of the image
    (a CFAR test assumes clutter dominates the scene; a region covering a large part of the
    image leaves no representative background, e.g. a 128x128 chip grown almost entirely)."""
    if p.max_size is not None and size > p.max_size:
        return True
    return p.max_fraction is not None and size > p.max_fraction * image_area


def _test_region(
    st: _ImageState, g: _Growth, idx: np.ndarray, imgs: tuple[np.ndarray, ...], p: RegionParams
) -> RegionRow:
    """Steps d–i for one grown region; returns its table row (label filled in later)."""
    h, w = st.shape
    seed = (int(idx[0]) // w, int(idx[0]) % w)
    nan = float("nan")
    if _too_large(idx.size, h * w, p):
        return RegionRow(seed, int(idx.size), nan, nan, nan, 0, -math.inf, False, "too_large")
    crop = crop_around(idx, (h, w), p.guard + p.background)
    raw, target_img, low = imgs
    rs = ring_stats(crop, raw, target_img, low, g.taken, p.guard, p.background)
    if rs.n_background < p.min_background:
        return RegionRow(
            seed,
            int(idx.size),
            rs.mu_t,
            rs.mu_c,
            rs.sigma_c,
            rs.n_background,
            -math.inf,
            False,
            "few_background",
        )
    z = _statistic(rs.mu_t, rs.mu_c, rs.sigma_c)
    ok = z > p.k
    return RegionRow(
        seed,
        int(idx.size),
        rs.mu_t,
        rs.mu_c,
        rs.sigma_c,
        rs.n_background,
        z,
        ok,
        "" if ok else "below_k",
    )


def _visit(
    st: _ImageState, g: _Growth, seed: int, imgs: tuple[np.ndarray, ...], p: RegionParams
) -> None:
    """Grow, test and record the region of one seed (steps c–i)."""
    tag = len(st.table) + 1
    idx = grow(g.grid, seed, tag, tau=p.tau, n_init=p.n_init, budget=p.budget, floor=p.floor)
    g.covered[idx] = True
    if p.blocking == "all":
        g.free[idx] = 0
    row = _test_region(st, g, idx, imgs, p)
    if row.accepted:
        g.taken.reshape(-1)[idx] = True
        g.free[idx] = 0
    better = st.stat[idx] < row.statistic
    st.stat[idx[better]] = row.statistic
    st.region_id[idx[better]] = tag
    st.table.rows.append(row)


def _visit_python(
    st: _ImageState,
    f: np.ndarray,
    seeds: np.ndarray,
    imgs: tuple[np.ndarray, ...],
    p: RegionParams,
) -> None:
    """Steps b–i for every seed with the Python heap, flood fills and numpy rings."""
    g = _Growth(f, p)
    for s in seeds.tolist():
        if not g.covered[s]:
            _visit(st, g, s, imgs, p)


def _compiled_seeds(f: Tensor, peaks: Tensor | None, p: RegionParams) -> np.ndarray:
    """The seeds, brightest first: from ``peaks`` if given, else found by the kernel."""
    if peaks is not None:
        return seed_order(f, peaks)
    from torchsar.region import _kernels

    h, w = f.shape
    flat = np.ascontiguousarray(f.numpy(), dtype=np.float64).reshape(-1)
    return _kernels.seeds(flat, h, w, p.seed_window)


def _visit_compiled(
    st: _ImageState,
    f: np.ndarray,
    seeds: np.ndarray,
    imgs: tuple[np.ndarray, ...],
    p: RegionParams,
) -> None:
    """Steps b–i for every seed in one compiled loop (:mod:`torchsar.region._kernels`);
    the same painted statistic, region ids and table as :func:`_visit_python`."""
    from torchsar.region import _kernels

    h, w = st.shape
    flat = [np.ascontiguousarray(a, dtype=np.float64).reshape(-1) for a in (f, *imgs)]
    out = _kernels.detect_loop(
        *flat,
        h,
        w,
        np.ascontiguousarray(seeds, dtype=np.int64),
        float(p.tau),
        p.n_init,
        p.guard,
        p.background,
        float(p.k),
        p.min_background,
        p.connectivity,
        p.blocking == "all",
        -1 if p.max_size is None else p.max_size,
        -1.0 if p.max_fraction is None else float(p.max_fraction),
        float(p.floor),
    )
    st.stat, st.region_id = out[0], out[1]
    seed, size, mu_t, mu_c, sigma_c, n_bg, z, ok, reason = (a.tolist() for a in out[2:])
    st.table.rows.extend(
        RegionRow(divmod(s, w), *row, REASONS[c])
        for s, c, *row in zip(seed, reason, size, mu_t, mu_c, sigma_c, n_bg, z, ok, strict=True)
    )


_EIGHT = np.ones((3, 3), dtype=bool)
_FOUR = ndimage.generate_binary_structure(2, 1)


def _drop_small_objects(st: _ImageState, min_size: int) -> None:
    """Reject accepted regions whose object (the 8-connected union of touching accepted
    regions) has fewer than ``min_size`` pixels: statistic ``-inf``, reason "too_small"."""
    if min_size <= 1:
        return
    stat = st.stat.reshape(st.shape)
    mask = stat > st.k
    box = mask_box(mask)
    if box is None:
        return
    lab, n = ndimage.label(mask[box], structure=_EIGHT)
    small = np.bincount(lab.reshape(-1), minlength=n + 1) < min_size  # per label
    small[0] = False
    if not small.any():
        return
    drop = small[lab]
    tags = np.unique(st.region_id.reshape(st.shape)[box][drop])
    stat[box][drop] = -np.inf
    for t in tags[tags > 0]:
        r = st.table.rows[t - 1]
        st.table.rows[t - 1] = RegionRow(**{**r.__dict__, "accepted": False, "reason": "too_small"})


def _fill_holes(st: _ImageState) -> None:
    """Give the pixels enclosed by accepted regions (holes, e.g. bright scatterers whose ring
    lay on the target itself and were rejected) to an adjacent accepted region: its statistic
    and its id. The table keeps each region's own decision.

    A hole is a 4-connected component of the unaccepted pixels that does not reach the image
    border (as :func:`scipy.ndimage.binary_fill_holes` defines it); its owner is the largest
    accepted id in the 3x3 neighbourhoods of its pixels. Holes lie inside the bounding box
    of the accepted pixels, so the work is done on that box padded by one unaccepted pixel
    (whose component is everything reaching the box's outside)."""
    h, w = st.shape
    mask = (st.stat > st.k).reshape(h, w)
    box = mask_box(mask)
    if box is None:
        return
    hb, wb = box[0].stop - box[0].start, box[1].stop - box[1].start
    m = np.zeros((hb + 2, wb + 2), dtype=bool)
    m[1:-1, 1:-1] = mask[box]
    lab, n = ndimage.label(~m, structure=_FOUR)
    inner = np.ones(n + 1, dtype=bool)
    inner[[0, lab[0, 0]]] = False
    rows, cols = np.nonzero(inner[lab])
    if rows.size == 0:
        return
    acc = np.zeros(m.shape, dtype=st.region_id.dtype)  # holes: >= 2 from its edge
    acc[1:-1, 1:-1] = np.where(mask[box], st.region_id.reshape(h, w)[box], 0)
    near = np.max([acc[rows + dr, cols + dc] for dr in (-1, 0, 1) for dc in (-1, 0, 1)], axis=0)
    owner = np.zeros(n + 1, dtype=np.int64)
    np.maximum.at(owner, lab[rows, cols], near)
    owner = owner[lab[rows, cols]]
    flat = (rows - 1 + box[0].start) * w + (cols - 1 + box[1].start)
    st.region_id[flat] = owner
    st.stat[flat] = np.array([st.table.rows[t - 1].statistic for t in owner.tolist()])


def _labels(st: _ImageState, mask: np.ndarray, merge: int | None) -> np.ndarray:
    """Region ids of the accepted regions: 1..n in acceptance order, or, with ``merge = d``,
    one id per group of accepted regions closer than ``d`` pixels (0: touching, including
    diagonally, like the evaluator's 8-connected objects)."""
    h, w = st.shape
    if merge is None:
        tags = np.array([i + 1 for i, r in enumerate(st.table.rows) if r.accepted], dtype=np.int64)
        lut = np.zeros(len(st.table) + 1, dtype=np.int64)
        lut[tags] = np.arange(1, tags.size + 1)
        return np.where(mask, lut[st.region_id], 0).reshape(h, w)
    m2 = mask.reshape(h, w)
    out = np.zeros((h, w), dtype=np.int64)
    box = mask_box(m2, merge)  # the dilated mask lies inside: same components, same numbering
    if box is not None:
        m = m2[box]
        grown = ndimage.binary_dilation(m, np.ones((2 * merge + 1,) * 2)) if merge else m
        lab, _ = ndimage.label(grown, structure=_EIGHT)
        out[box] = np.where(m, lab, 0)
    return out


def _fill_holes_compiled(st: _ImageState) -> None:
    """:func:`_fill_holes`, compiled (the same result)."""
    from torchsar.region import _kernels

    z = np.array([r.statistic for r in st.table.rows], dtype=np.float64)
    _kernels.fill_holes(st.stat, st.region_id, *st.shape, float(st.k), z)


def _drop_small_compiled(st: _ImageState, min_size: int) -> None:
    """:func:`_drop_small_objects`, compiled (the same result)."""
    from torchsar.region import _kernels

    if min_size <= 1:
        return
    rows = st.table.rows
    dropped = _kernels.drop_small_objects(
        st.stat, st.region_id, *st.shape, float(st.k), min_size, len(rows)
    )
    for t in np.flatnonzero(dropped[1:]).tolist():
        rows[t] = RegionRow(**{**rows[t].__dict__, "accepted": False, "reason": "too_small"})


def _labels_compiled(st: _ImageState, mask: np.ndarray, merge: int | None) -> np.ndarray:
    """:func:`_labels`, compiled for ``merge`` not None (the same result)."""
    from torchsar.region import _kernels

    if merge is None:
        return _labels(st, mask, merge)
    return _kernels.merged_labels(mask, *st.shape, merge).reshape(st.shape)


def _finish_table(st: _ImageState, labels: np.ndarray) -> None:
    """Write each accepted region's final label into its table row."""
    rows = st.table.rows
    for i, r in enumerate(rows):
        if r.accepted:
            rows[i] = RegionRow(**{**r.__dict__, "label": int(labels[r.seed])})


def detect_image(
    raw: Tensor,
    f: Tensor,
    target_img: Tensor,
    low: Tensor,
    p: RegionParams,
    dtype: np.dtype,
    peaks: Tensor | None,
) -> tuple[np.ndarray, np.ndarray, RegionTable]:
    """Run steps b–j on one image (``(H, W)`` float64 CPU tensors); ``peaks`` is the bool
    ``(H, W)`` seed mask of step a (:func:`~torchsar.region.seeds.local_maxima` of ``f``,
    computed by the caller for a whole batch at once), or None: found here (by the kernel
    on the compiled path).

    Returns the painted statistic ``(H, W)`` in ``dtype``, the labels ``(H, W)`` int64 (of
    the pixels where ``statistic > k`` in that dtype) and the region table.
    """
    st = _ImageState(f, p)
    imgs = (raw.numpy(), target_img.numpy(), low.numpy())
    if _jit.enabled():
        _visit_compiled(st, f.numpy(), _compiled_seeds(f, peaks, p), imgs, p)
        fill, drop, label = _fill_holes_compiled, _drop_small_compiled, _labels_compiled
    else:
        peaks = local_maxima(f[None, None], p.seed_window)[0, 0] if peaks is None else peaks
        _visit_python(st, f.numpy(), seed_order(f, peaks), imgs, p)
        fill, drop, label = _fill_holes, _drop_small_objects, _labels
    if p.fill_holes:
        fill(st)
    drop(st, p.min_size)
    stat = st.stat.astype(dtype)
    mask = stat > dtype.type(p.k)
    labels = label(st, mask, p.merge)
    _finish_table(st, labels)
    return stat.reshape(st.shape), labels, st.table
