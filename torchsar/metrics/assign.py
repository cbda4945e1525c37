"""Match a batch of scored objects to its ground truth (see :mod:`torchsar.metrics.matching`
for the rules), every plane and class at once.

A *problem* is a plane (class-agnostic matching) or a (plane, class) pair (class-aware: a
detection only meets targets and don't-care regions of its own class; a region without a
class meets every detection). Within a problem the detections are visited in descending
score order (ties: the order given) and the targets in their order, followed by the
problem's don't-care regions as crowd instances (:mod:`torchsar.metrics.greedy`).

Only pairs that can match take part: pairs whose quality is positive (a mask intersection,
a box intersection, a centroid inside the grown box). Mask IoU needs the pixels of both
(objects with masks and targets given as masks); every other pair is compared by box, so
box ground truth with box detections never touches a pixel.

AP is matched as ``pycocotools`` matches it: per area range (``all``, then COCO's small /
medium / large: a target outside the range is ignored, as is a detection left unmatched
outside it) and per IoU threshold of :data:`~torchsar.metrics.matching.COCO_IOUS`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from torchsar import _jit
from torchsar.metrics.batch import BatchMatch, by_plane
from torchsar.metrics.greedy import assign_pairs
from torchsar.metrics.matching import COCO_IOUS, Matching, pair_box_iou
from torchsar.metrics.points import match_points
from torchsar.metrics.truth import GroundTruth
from torchsar.objects import Objects

__all__ = [
    "AP_AREAS",
    "BatchMatch",
    "by_plane",
    "join_pixels",
    "match_batch",
    "measured_as",
    "pixel_pairs",
    "point_pixels",
    "region_lists",
    "same_plane_pairs",
    "touching_pairs",
]

AP_AREAS: dict[str, tuple[float, float]] = {
    "all": (0.0, 1e10),
    "small": (0.0, 32.0**2),
    "medium": (32.0**2, 96.0**2),
    "large": (96.0**2, 1e10),
}
"""COCO's area ranges of AP (``pycocotools`` ``areaRng``, bounds inclusive), by name."""
_RANGES = np.array(list(AP_AREAS.values()))


def same_plane_pairs(plane_d: np.ndarray, plane_g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every ``(detection, target)`` index pair that shares a key (a plane, a problem).

    Examples:
        >>> [a.tolist() for a in same_plane_pairs(np.array([0, 1, 1]), np.array([1, 0]))]
        [[0, 1, 2], [1, 0, 0]]
    """
    order_g = np.argsort(plane_g, kind="stable")
    lo = np.searchsorted(plane_g[order_g], plane_d, side="left")
    n = np.searchsorted(plane_g[order_g], plane_d, side="right") - lo
    d = np.repeat(np.arange(plane_d.size), n)
    start = np.repeat(lo - np.concatenate([[0], np.cumsum(n)[:-1]]), n)
    return d, order_g[np.arange(d.size) + start]


def point_pixels(obj: Objects) -> np.ndarray:
    """Flat stack index of the pixel under each point object."""
    h, w = obj.shape
    r = np.clip(np.floor(obj.centroid[:, 0] + 0.5), 0, h - 1).astype(np.int64)
    c = np.clip(np.floor(obj.centroid[:, 1] + 0.5), 0, w - 1).astype(np.int64)
    return obj.plane * (h * w) + r * w + c


DENSE_LOOKUP = 1 << 22
"""Pixel index range always joined through a dense lookup table; beyond it only when the
range is at most 16 times the pixels joined (else by sorting: memory follows the pixels)."""


def join_pixels(a_owner: np.ndarray, a_pix: np.ndarray, b_owner: np.ndarray, b_pix: np.ndarray):
    """Pixel intersections of two sets of pixel lists: ``(a, b, shared pixels)`` for every
    pair sharing a pixel, ascending by ``(a, b)`` (the ``b`` lists may overlap each other:
    then by sorting, else by a dense lookup of the ``b`` owners over the pixel range; with
    the compiled kernels in one call: :func:`torchsar.metrics._match_kernels.join_pixels`)."""
    if a_pix.size == 0 or b_pix.size == 0:
        z = np.zeros(0, np.int64)
        return z, z, z
    if _jit.enabled():  # one compiled call: the same pairs and counts
        from torchsar.metrics import _match_kernels

        a_owner, a_pix, b_owner, b_pix = (
            np.asarray(v, np.int64) for v in (a_owner, a_pix, b_owner, b_pix)
        )
        if not _match_kernels.ascending(b_pix):  # (ground truth's lists usually are)
            order = np.argsort(b_pix, kind="stable")
            b_owner, b_pix = b_owner[order], b_pix[order]
        return _match_kernels.join_pixels(a_owner, a_pix, b_owner, b_pix)
    top = int(max(a_pix.max(), b_pix.max())) + 1
    if top <= max(DENSE_LOOKUP, 16 * (a_pix.size + b_pix.size)) and b_owner.max() < 2**31 - 2:
        lut = np.zeros(top, np.int32)
        lut[b_pix] = b_owner + 1
        if np.count_nonzero(lut) == b_pix.size:  # no pixel in two b lists
            hit = lut[a_pix]
            n_b = int(b_owner.max()) + 1
            sel = hit > 0
            key = a_owner[sel].astype(np.int64) * (n_b + 1) + (hit[sel] - 1)
            pairs, inter = np.unique(key, return_counts=True)
            return pairs // (n_b + 1), pairs % (n_b + 1), inter.astype(np.int64)
    order = np.argsort(b_pix, kind="stable")
    bp, bo = b_pix[order], b_owner[order]
    lo = np.searchsorted(bp, a_pix, side="left")
    n = np.searchsorted(bp, a_pix, side="right") - lo
    hit = np.flatnonzero(n)
    ai = np.repeat(hit, n[hit])
    bi = np.repeat(lo[hit], n[hit]) + _within(n[hit])
    n_b = int(b_owner.max(initial=-1)) + 1
    key = a_owner[ai].astype(np.int64) * (n_b + 1) + bo[bi]
    pairs, inter = np.unique(key, return_counts=True)
    return pairs // (n_b + 1), pairs % (n_b + 1), inter.astype(np.int64)


def _within(sizes: np.ndarray) -> np.ndarray:
    return np.arange(int(sizes.sum())) - np.repeat(np.cumsum(sizes) - sizes, sizes)


def pixel_pairs(obj: Objects, gt: GroundTruth) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every ``(detection, target)`` pair sharing pixels, with the shared pixel count: objects
    with masks against targets with pixels (box targets given without pixels never share
    one)."""
    cache = gt.__dict__.setdefault("_pixel_pairs", {})
    key = id(obj)
    if key not in cache or cache[key][0] is not obj:  # the same objects: joined once
        owner, idx = obj.pixel_lists()
        cache.clear()
        cache[key] = (obj, join_pixels(owner, idx, gt.masks.owner(), gt.masks.pixels))
    return cache[key][1]


def _box_cover(pixels: np.ndarray, shape: tuple[int, int], boxes: np.ndarray) -> np.ndarray:
    """Area of each box ``(r0, c0, r1, c1)`` covered by a region of pixels (flat stack
    indices on one plane, each pixel the unit square it spans): exact, by an integral image
    over the region's extent (a box's rows and columns cut in three: the partly covered first
    and last, the wholly covered middle)."""
    h, w = shape
    local = pixels % (h * w)
    r, c = local // w, local % w
    r0, c0 = int(r.min()), int(c.min())
    grid = np.zeros((int(r.max()) - r0 + 2, int(c.max()) - c0 + 2), np.int64)
    np.add.at(grid, (r - r0 + 1, c - c0 + 1), 1)
    ii = grid.cumsum(0).cumsum(1)
    rows = _thirds(boxes[:, 0] - r0, boxes[:, 2] - r0, ii.shape[0] - 1)
    cols = _thirds(boxes[:, 1] - c0, boxes[:, 3] - c0, ii.shape[1] - 1)
    out = np.zeros(boxes.shape[0])
    for a, b, wr in rows:
        for c_, d, wc in cols:
            n = ii[b, d] - ii[a, d] - ii[b, c_] + ii[a, c_]
            out += np.where((b > a) & (d > c_), n * wr * wc, 0.0)
    return out


def _thirds(lo: np.ndarray, hi: np.ndarray, n: int) -> list[tuple]:
    """The pixel rows ``[lo, hi)`` (fractional) of each box in three runs ``(start, end,
    weight)``: the first pixel (partly covered), the middle ones (whole), the last (partly),
    clipped to ``[0, n)``; a box within one pixel is that pixel alone."""
    first = np.floor(lo)
    last = np.ceil(hi) - 1
    one = last <= first
    w_first = np.where(one, hi - lo, first + 1 - lo)
    w_last = np.where(one, 0.0, hi - last)

    def clip(v):
        return np.clip(v, 0, n).astype(np.int64)

    return [
        (clip(first), clip(first + 1), w_first),
        (clip(first + 1), clip(np.maximum(last, first + 1)), np.ones(lo.shape)),
        (clip(np.maximum(last, first + 1)), clip(np.maximum(last + 1, first + 1)), w_last),
    ]


def _classes(obj: Objects, rule: Matching) -> bool:
    """Whether the batch is matched within classes: the rule asks for it (``"auto"``) and
    the detections carry classes."""
    return rule.classes != "agnostic" and obj.classes is not None


@dataclass(frozen=True)
class _Problems:
    """The instances of every problem: the targets, then the don't-care regions that apply
    (crowd), numbered problem by problem; detections likewise."""

    d_order: np.ndarray  # detections in visiting order (problem, descending score)
    d_problem: np.ndarray  # problem of each, in that order
    i_problem: np.ndarray  # problem of each instance (sorted)
    i_target: np.ndarray  # target index of each instance (-1: a region)
    i_region: np.ndarray  # region index (-1: a target)


def _problems(obj: Objects, gt: GroundTruth, by_class: bool) -> _Problems:
    names = sorted(
        {*map(str, gt.classes.tolist()), *(map(str, obj.classes.tolist()) if by_class else ())}
    )
    code = {n: k for k, n in enumerate(names)}
    n_cls = max(len(names), 1)
    if by_class:
        d_key = obj.plane * n_cls + np.array(
            [code[str(c)] for c in obj.classes.tolist()], dtype=np.int64
        ).reshape(-1)
        g_key = gt.plane * n_cls + np.array(
            [code[str(c)] for c in gt.classes.tolist()], dtype=np.int64
        ).reshape(-1)
    else:
        d_key, g_key = obj.plane.astype(np.int64), gt.plane.astype(np.int64)
    d_order = np.lexsort((np.arange(len(obj)), -obj.score, d_key))
    # regions: one crowd instance per problem of their plane they apply to
    reg = gt.crowd
    if by_class:
        r_cls = [code.get(str(c), -1) if c is not None else None for c in reg.classes.tolist()]
        keys, idx = [], []
        present = np.unique(d_key)
        for k, c in enumerate(r_cls):
            if c is None:  # every class: every class problem of the plane with detections
                mine = present[present // n_cls == reg.plane[k]]
            else:
                mine = np.array([reg.plane[k] * n_cls + c]) if c >= 0 else np.zeros(0, np.int64)
            keys.append(mine)
            idx.append(np.full(mine.size, k))
        r_key = np.concatenate(keys) if keys else np.zeros(0, np.int64)
        r_idx = np.concatenate(idx) if idx else np.zeros(0, np.int64)
    else:
        r_key, r_idx = reg.plane.astype(np.int64), np.arange(len(reg))
    i_key = np.concatenate([g_key, r_key]).astype(np.int64)
    i_target = np.concatenate([np.arange(len(gt)), np.full(r_key.size, -1)]).astype(np.int64)
    i_region = np.concatenate([np.full(len(gt), -1), r_idx]).astype(np.int64)
    is_region = i_region >= 0
    order = np.lexsort((np.arange(i_key.size), is_region, i_key))  # targets, then regions
    # dense problem numbers over detections and instances
    keys, inv = np.unique(np.concatenate([d_key[d_order], i_key[order]]), return_inverse=True)
    return _Problems(d_order, inv[: len(obj)], inv[len(obj) :], i_target[order], i_region[order])


def _det_area(obj: Objects, boxes: bool = False) -> np.ndarray:
    """Each detection's own area for COCO's area ranges: its pixels (masks), ``w * h``
    (boxes, or every object with ``boxes``), 0 (points). (``pycocotools`` reads a results
    entry's ``bbox`` ``w * h`` even for a mask: only the COCO-compatible state follows it,
    :attr:`~torchsar.objects.Objects.declared_area`.)"""
    if obj.geometry == "box" or (boxes and obj.geometry == "mask"):
        return (obj.box[:, 2] - obj.box[:, 0]) * (obj.box[:, 3] - obj.box[:, 1])
    return obj.area.astype(np.float64)


@dataclass(frozen=True)
class _Pairs:
    """Candidate pairs (visiting-order detection ``d``, instance ``i``) with their IoU and
    the rule's quality; region pairs carry their crowd quality in both."""

    d: np.ndarray
    i: np.ndarray
    iou: np.ndarray


def _target_iou(
    obj: Objects, gt: GroundTruth, rule: Matching, od: np.ndarray, g: np.ndarray, inter: tuple
) -> np.ndarray:
    """IoU of object ``od[k]`` with target ``g[k]``: mask IoU where both are masks and the
    rule reads masks, else box IoU (``inter``: the pixel intersections, :func:`pixel_pairs`)."""
    out = pair_box_iou(obj.box[od], gt.box[g])
    if rule.iou_kind != "mask" or not obj.has_masks or not gt.has_mask.any():
        return out
    use = gt.has_mask[g]
    jd, jg, jn = inter
    n_g = len(gt) + 1
    shared = _lookup(jd * n_g + jg, jn, od[use] * n_g + g[use]).astype(np.float64)
    union = obj.area[od[use]] + gt.area[g[use]] - shared
    out[use] = np.where(union > 0, shared / np.where(union > 0, union, 1), 0.0)
    return out


def measured_as(obj: Objects, gt: GroundTruth, rule: Matching) -> set[str]:
    """The IoU that AP (and an IoU rule's operating point) measures on the pairs of ``obj``
    and ``gt``, as :func:`_target_iou` computes it: ``{"mask"}`` (masks on both sides, any
    rule but the box rule: the centroid rule's AP too), ``{"box"}`` (the box rule, box
    objects, or box targets), both (some targets masks, some boxes), ``{"point"}`` (points:
    no AP at an IoU), or ``{"distance"}`` under the distance rule. Nothing without targets
    (there is nothing to measure against)."""
    if rule.kind == "distance":
        return {"distance"}
    if len(gt) == 0:
        return set()
    if obj.geometry == "point":
        return {"point"}
    if rule.iou_kind == "mask" and obj.has_masks and gt.has_mask.any():
        return {"mask"} if gt.has_mask.all() else {"mask", "box"}
    return {"box"}


def region_lists(gt: GroundTruth, boxes: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """``(owner, flat index)`` of every don't-care region's pixels (box regions rasterised,
    or left out without ``boxes``)."""
    parts = [
        gt.region_pixels(k) if boxes or gt.crowd.has_mask[k] else np.zeros(0, np.int64)
        for k in range(len(gt.crowd))
    ]
    owner = np.repeat(np.arange(len(parts)), [p.size for p in parts])
    return owner, np.concatenate(parts) if parts else np.zeros(0, np.int64)


def _lookup(keys: np.ndarray, values: np.ndarray, want: np.ndarray) -> np.ndarray:
    """``values`` at the positions of ``want`` in ``keys`` (0 where absent)."""
    if keys.size == 0:
        return np.zeros(want.size, values.dtype)
    order = np.argsort(keys, kind="stable")
    pos = np.minimum(np.searchsorted(keys[order], want), keys.size - 1)
    return np.where(keys[order][pos] == want, values[order][pos], 0)


def _crowd_quality(
    obj: Objects, gt: GroundTruth, od: np.ndarray, k: np.ndarray, boxes: bool = False
) -> np.ndarray:
    """Share of object ``od[j]`` lying on don't-care region ``k[j]`` (COCO's crowd rule:
    intersection over the object's own area; a point: 1 on the region, else 0). Masks and
    mask regions intersect by pixels; a box meets a mask region, and a mask a box region, by
    the exact area the pixel squares and the box share. ``boxes``: objects with masks count
    as their boxes (the box rule)."""
    reg, n_k = gt.crowd, len(gt.crowd) + 1
    out = np.zeros(od.size)
    if od.size == 0:
        return out
    if obj.geometry == "point" or (obj.has_masks and not boxes):
        r_owner, r_pix = region_lists(gt, boxes=obj.geometry == "point")
        if obj.geometry == "point":
            owner, idx = np.arange(len(obj)), point_pixels(obj)
        else:
            owner, idx = obj.pixel_lists()
        jd, jk, jn = join_pixels(owner, idx, r_owner, r_pix)
        shared = _lookup(jd * n_k + jk, jn, od * n_k + k).astype(np.float64)
        if obj.geometry == "point":
            return (shared > 0).astype(np.float64)
        out = shared / np.maximum(obj.area[od], 1)
        boxed = ~reg.has_mask[k]
        if boxed.any():
            out[boxed] = _pixels_on_box(obj, od[boxed], reg.box[k[boxed]])
        return out
    area = _det_area(obj, boxes=True)[od]  # boxes
    h, w = gt.shape
    for r in np.unique(k):
        sel = np.flatnonzero(k == r)
        if reg.has_mask[r]:
            pix = reg.masks.of(int(r))
            cover = _box_cover(pix, (h, w), obj.box[od[sel]]) if pix.size else 0.0
            out[sel] = np.where(area[sel] > 0, cover / np.where(area[sel] > 0, area[sel], 1), 0)
        else:
            out[sel] = pair_box_iou(obj.box[od[sel]], reg.box[r][None], crowd=True)
    return out


def _pixels_on_box(obj: Objects, od: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Share of each mask object ``od[j]``'s pixel squares lying in box ``boxes[j]``."""
    owner, idx = obj.pixel_lists()
    h, w = obj.shape
    out = np.zeros(od.size)
    for j, (d, b) in enumerate(zip(od, boxes, strict=True)):
        pix = idx[owner == d] % (h * w)
        r, c = pix // w, pix % w
        ov_r = np.clip(np.minimum(r + 1, b[2]) - np.maximum(r, b[0]), 0, None)
        ov_c = np.clip(np.minimum(c + 1, b[3]) - np.maximum(c, b[1]), 0, None)
        out[j] = float((ov_r * ov_c).sum()) / max(int(obj.area[d]), 1)
    return out


def _centroid_pairs(cen: np.ndarray, db: np.ndarray, gb: np.ndarray, m: Matching) -> np.ndarray:
    """Prescreening pair quality ``1 / (1 + distance to the box centre)``, 0 where the
    centroid is outside the grown box or the detection box is too large (centroids and
    boxes ``(..., 2)`` / ``(..., 4)``, paired by broadcasting)."""
    cen = cen + 0.5  # pixel centres, in box coordinates
    grow = m.margin * np.maximum(gb[..., 2] - gb[..., 0], gb[..., 3] - gb[..., 1])
    inside = (
        (cen[..., 0] >= gb[..., 0] - grow)
        & (cen[..., 0] <= gb[..., 2] + grow)
        & (cen[..., 1] >= gb[..., 1] - grow)
        & (cen[..., 1] <= gb[..., 3] + grow)
    )
    area_d = (db[..., 2] - db[..., 0]) * (db[..., 3] - db[..., 1])
    area_g = (gb[..., 2] - gb[..., 0]) * (gb[..., 3] - gb[..., 1])
    ok = inside & (area_d <= m.max_size_ratio * area_g)
    mid = 0.5 * (gb[..., :2] + gb[..., 2:])
    dist = np.hypot(cen[..., 0] - mid[..., 0], cen[..., 1] - mid[..., 1])
    return np.where(ok, 1.0 / (1.0 + dist), 0.0)


def _boxes_meet(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether boxes ``a[k]`` and ``b[k]`` share some area."""
    return (np.minimum(a[:, 2], b[:, 2]) > np.maximum(a[:, 0], b[:, 0])) & (
        np.minimum(a[:, 3], b[:, 3]) > np.maximum(a[:, 1], b[:, 1])
    )


def touching_pairs(obj: Objects, gt: GroundTruth) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every ``(detection, target)`` pair that touches, with their shared pixels: objects with
    masks and targets with pixels share pixels; a point touches a target when its pixel is
    one of the target's (or lies in a box target's box); everything else touches when the
    boxes intersect (shared pixels 0)."""
    pixelled = np.diff(gt.masks.offsets) > 0
    if obj.geometry == "point":
        at = point_pixels(obj)
        d, g, n = join_pixels(np.arange(len(obj)), at, gt.masks.owner(), gt.masks.pixels)
        rest_d, rest_g = same_plane_pairs(obj.plane, gt.plane)
        keep = ~pixelled[rest_g]
        rest_d, rest_g = rest_d[keep], rest_g[keep]
        p = point_pixels(obj)[rest_d] % (gt.shape[0] * gt.shape[1])
        r, c = p // gt.shape[1] + 0.5, p % gt.shape[1] + 0.5
        b = gt.box[rest_g]
        inside = (r >= b[:, 0]) & (r < b[:, 2]) & (c >= b[:, 1]) & (c < b[:, 3])
        z = np.zeros(int(inside.sum()), np.int64)
        return (
            np.concatenate([d, rest_d[inside]]),
            np.concatenate([g, rest_g[inside]]),
            np.concatenate([n, z]),
        )
    if obj.has_masks:
        d, g, n = pixel_pairs(obj, gt)
        rest_d, rest_g = same_plane_pairs(obj.plane, gt.plane)
        keep = ~pixelled[rest_g]
    else:
        d, g, n = (np.zeros(0, np.int64),) * 3
        rest_d, rest_g = same_plane_pairs(obj.plane, gt.plane)
        keep = np.ones(rest_d.size, bool)
    rest_d, rest_g = rest_d[keep], rest_g[keep]
    meet = _boxes_meet(obj.box[rest_d], gt.box[rest_g])
    z = np.zeros(int(meet.sum()), np.int64)
    return (
        np.concatenate([d, rest_d[meet]]),
        np.concatenate([g, rest_g[meet]]),
        np.concatenate([n, z]),
    )


def _outside(area: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """``(N, A)``: area outside each range, pycocotools' ``area < lo or area > hi``."""
    return (area[:, None] < ranges[:, 0]) | (area[:, None] > ranges[:, 1])


def match_batch(obj: Objects, gt: GroundTruth, rule: Matching) -> BatchMatch:
    """Match every plane's objects to its targets (objects and targets of the same stack of
    planes; see the module docstring); the distance rule by
    :func:`torchsar.metrics.points.match_points`. A finite box whose area overflows float
    range (1e300 px a side) has area ``inf``, as in pycocotools: it matches nothing."""
    with np.errstate(over="ignore", invalid="ignore"):
        return _match_batch(obj, gt, rule)


def _match_batch(obj: Objects, gt: GroundTruth, rule: Matching) -> BatchMatch:
    if rule.kind == "distance":
        return match_points(obj, gt, rule)
    by_class = _classes(obj, rule)
    pr = _problems(obj, gt, by_class)
    dv, iv = same_plane_pairs(pr.d_problem, pr.i_problem)
    od, tg, rg = pr.d_order[dv], pr.i_target[iv], pr.i_region[iv]
    is_t = tg >= 0
    masks = obj.has_masks and rule.iou_kind == "mask" and bool(gt.has_mask.any())
    inter = pixel_pairs(obj, gt) if masks else (np.zeros(0, np.int64),) * 3
    iou = np.zeros(dv.size)
    iou[is_t] = _target_iou(obj, gt, rule, od[is_t], tg[is_t], inter)
    crowd = _crowd_quality(obj, gt, od[~is_t], rg[~is_t], boxes=rule.iou_kind == "box")
    quality = iou.copy()
    quality[~is_t] = crowd
    n_inst = pr.i_problem.size
    i_ignore = np.ones((n_inst, _RANGES.shape[0]), bool)
    real = pr.i_target >= 0
    i_ignore[real] = _outside(gt.coco_area[pr.i_target[real]], _RANGES)
    i_crowd = ~real
    keep = quality > 0
    col = assign_pairs(
        pr.d_problem,
        pr.i_problem,
        i_ignore,
        i_crowd,
        (dv[keep], iv[keep], quality[keep]),
        COCO_IOUS,
    )
    d_area = _det_area(obj, boxes=rule.iou_kind == "box")[pr.d_order]
    d_out = _outside(d_area, _RANGES)
    ap = _statuses(col, pr, i_ignore, d_out)
    if rule.kind == "centroid":
        q = np.zeros(dv.size)
        q[is_t] = _centroid_pairs(obj.centroid[od[is_t]], obj.box[od[is_t]], gt.box[tg[is_t]], rule)
        q[~is_t] = (crowd >= 0.5).astype(np.float64)  # COCO's crowd rule at 0.5
        keep = q > 0
        opc = assign_pairs(
            pr.d_problem,
            pr.i_problem,
            i_ignore[:, :1],
            i_crowd,
            (dv[keep], iv[keep], q[keep]),
            [1e-12],
        )
        op_v = _statuses(opc, pr, i_ignore[:, :1], np.zeros((len(obj), 1), bool))
    elif rule.iou == COCO_IOUS[0] and not d_out[:, 0].any():
        op_v = ap[:1, :1]  # (the operating point ignores no detection for its size: a box
        # past COCO's area range "all", 1e10 px, is a false alarm there, not ignored)
    else:
        opc = assign_pairs(
            pr.d_problem,
            pr.i_problem,
            i_ignore[:, :1],
            i_crowd,
            (dv[keep], iv[keep], quality[keep]),
            [rule.iou],
        )
        op_v = _statuses(opc, pr, i_ignore[:, :1], np.zeros((len(obj), 1), bool))
    return _result(obj, gt, rule, pr, ap, op_v[0, 0], inter, by_class)


def _statuses(col: np.ndarray, pr: _Problems, i_ignore: np.ndarray, d_out: np.ndarray):
    """``(A, T, D)`` statuses in visiting order: target index, -1 false, -2 ignored (took an
    ignored instance, or unmatched outside the area range)."""
    took = col >= 0
    inst = np.maximum(col, 0)
    a_idx = np.arange(col.shape[1])[None, :, None]
    pad_ignore = np.vstack([i_ignore, np.zeros((1, i_ignore.shape[1]), bool)])
    pad_target = np.append(pr.i_target, -1)
    inst = np.where(took, inst, i_ignore.shape[0])  # the padding row where nothing was taken
    out = np.where(took, np.where(pad_ignore[inst, a_idx], -2, pad_target[inst]), -1)
    out = np.where((out == -1) & d_out[:, :, None], -2, out)
    return out.transpose(1, 2, 0)


def _result(obj, gt, rule, pr, ap_v, op_v, inter, by_class) -> BatchMatch:
    """The batch's :class:`BatchMatch` from the statuses in visiting order."""
    n_d, n_g = len(obj), len(gt)
    ap = np.empty(ap_v.shape, np.int64)
    ap[:, :, pr.d_order] = ap_v
    op = np.empty(n_d, np.int64)
    op[pr.d_order] = op_v
    hit = np.flatnonzero(op >= 0)
    op_iou = np.zeros(n_d)
    op_iou[hit] = _target_iou(obj, gt, rule, hit, op[hit], inter)
    gt_det = np.full(n_g, -1, np.int64)
    gt_det[op[hit]] = hit
    gt_score = np.where(gt_det >= 0, obj.score[np.maximum(gt_det, 0)] if n_d else 0, -np.inf)
    _, g, _ = touching_pairs(obj, gt)
    touch = np.bincount(g, minlength=n_g).astype(np.int64)
    kind = "iou" if obj.geometry != "point" else "none"
    return BatchMatch(ap, op, op_iou, gt_score, touch, gt_det, kind, by_class)
