"""Match a batch of scored objects to its ground truth, plane by plane (see
:mod:`torchsar.metrics.matching` for the rules)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from torchsar.metrics.matching import (
    COCO_IOUS,
    GroundTruth,
    Matching,
    box_iou,
    first_reach,
    greedy_match_planes,
    pair_box_iou,
)
from torchsar.objects import Objects

__all__ = ["BatchMatch", "Overlaps", "by_plane", "match_batch"]


@dataclass(frozen=True)
class BatchMatch:
    """Assignments of one batch.

    Attributes:
        ap: int ``(10, M)`` per COCO IoU threshold: matched instance index, -1 false, -2
            ignored (IoU of :attr:`Matching.iou_kind`).
        op: int ``(M,)`` the same under the matching rule.
        op_iou: float ``(M,)`` IoU of each detection with the instance it matched under the
            rule (0 when unmatched).
        gt_score: float ``(G,)`` score of the detection that matched each instance under the
            rule (``-inf``: missed).
        gt_det: int ``(G,)`` index of that detection (-1: missed).
        overlaps: int ``(G,)`` number of detections touching each instance (fragmentation).
    """

    ap: np.ndarray
    op: np.ndarray
    op_iou: np.ndarray
    gt_score: np.ndarray
    overlaps: np.ndarray
    gt_det: np.ndarray
    ap_kind: str = "iou"


def by_plane(plane: np.ndarray, n_planes: int) -> list[np.ndarray]:
    """Indices of the items of each plane (``plane``: each item's plane), in item order."""
    order = np.argsort(plane, kind="stable")
    cuts = np.searchsorted(plane[order], np.arange(n_planes + 1))
    return [order[cuts[p] : cuts[p + 1]] for p in range(n_planes)]


def _centroid_quality(obj: Objects, gt: GroundTruth, d: np.ndarray, g: np.ndarray, m: Matching):
    """Prescreening quality matrix ``(len(d), len(g))``, see :func:`_centroid_pairs`."""
    return _centroid_pairs(obj.centroid[d][:, None, :], obj.box[d][:, None, :],
                           gt.box[g][None, :, :], m)  # fmt: skip


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


class Overlaps:
    """Pixel intersections of the batch's objects with its instances and ignore pixels
    (objects with masks, from their pixel lists; a box or a point covers no pixel here, see
    :func:`_touching`)."""

    def __init__(self, obj: Objects, gt: GroundTruth) -> None:
        n_d, n_g = len(obj), len(gt)
        owner, idx = obj.pixel_lists()  # (none for boxes and points)
        gid = gt.ids.reshape(-1)[idx]
        both = gid > 0
        key = owner[both] * (n_g + 1) + gid[both]
        pairs, self.inter = np.unique(key, return_counts=True)
        self.d, self.g = pairs // (n_g + 1), pairs % (n_g + 1) - 1
        self.ignored = np.bincount(owner[gt.ignore.reshape(-1)[idx]], minlength=n_d)
        self.touch = np.bincount(self.g, minlength=n_g) if obj.has_masks else _touching(obj, gt)

    def mask_iou(self, obj: Objects, gt: GroundTruth, d: np.ndarray, g: np.ndarray):
        pos_d = np.full(len(obj), -1)
        pos_d[d] = np.arange(d.size)
        pos_g = np.full(len(gt), -1)
        pos_g[g] = np.arange(g.size)
        sel = (pos_d[self.d] >= 0) & (pos_g[self.g] >= 0)
        dd, gg, inter = self.d[sel], self.g[sel], self.inter[sel]
        iou = np.zeros((d.size, g.size))
        iou[pos_d[dd], pos_g[gg]] = inter / (obj.area[dd] + gt.area[gg] - inter)
        return iou, self.crowd(obj, d)

    def crowd(self, obj: Objects, d: np.ndarray) -> np.ndarray:
        """Fraction of each detection's pixels on the ignore region (COCO's crowd rule)."""
        return self.ignored[d] / np.maximum(obj.area[d], 1)

    def pair_iou(self, obj: Objects, gt: GroundTruth, d: np.ndarray, g: np.ndarray):
        """Mask IoU of each detection ``d[i]`` with instance ``g[i]``, where every detection
        meets no instance but possibly ``g[i]`` (its plane's only one)."""
        inter = np.zeros(len(obj))
        inter[self.d] = self.inter
        inter = inter[d]
        return inter / (obj.area[d] + gt.area[g] - inter)


def _same_plane_pairs(plane_d: np.ndarray, plane_g: np.ndarray) -> tuple[np.ndarray, ...]:
    """Every ``(detection, instance)`` index pair that shares a plane."""
    order_g = np.argsort(plane_g, kind="stable")
    lo = np.searchsorted(plane_g[order_g], plane_d, side="left")
    n = np.searchsorted(plane_g[order_g], plane_d, side="right") - lo
    d = np.repeat(np.arange(plane_d.size), n)
    start = np.repeat(lo - np.concatenate([[0], np.cumsum(n)[:-1]]), n)
    return d, order_g[np.arange(d.size) + start]


def _touching(obj: Objects, gt: GroundTruth) -> np.ndarray:
    """Detections touching each instance, for boxes (box intersection) and points (the
    point's pixel lies on the instance)."""
    if obj.geometry == "point":
        gid = gt.ids.reshape(-1)[_point_pixels(obj)]
        return np.bincount(gid[gid > 0] - 1, minlength=len(gt))
    d, g = _same_plane_pairs(obj.plane, gt.plane)
    a, b = obj.box[d], gt.box[g]
    meet = (np.minimum(a[:, 2], b[:, 2]) > np.maximum(a[:, 0], b[:, 0])) & (
        np.minimum(a[:, 3], b[:, 3]) > np.maximum(a[:, 1], b[:, 1]))  # fmt: skip
    return np.bincount(g[meet], minlength=len(gt))


def _point_pixels(obj: Objects) -> np.ndarray:
    """Flat stack index of the pixel under each point object."""
    h, w = obj.shape
    r = np.clip(np.floor(obj.centroid[:, 0] + 0.5), 0, h - 1).astype(np.int64)
    c = np.clip(np.floor(obj.centroid[:, 1] + 0.5), 0, w - 1).astype(np.int64)
    return obj.plane * (h * w) + r * w + c


def _box_crowd(obj: Objects, gt: GroundTruth, d: np.ndarray, ig_box: np.ndarray) -> np.ndarray:
    """The crowd quality of detections without masks: a box's intersection with the
    bounding box of its plane's ignore pixels over its area (COCO's bbox rule); a point's is
    1 on an ignore pixel, else 0."""
    if obj.geometry == "point":
        return gt.ignore.reshape(-1)[_point_pixels(obj)[d]].astype(np.float64)
    return pair_box_iou(obj.box[d], ig_box[obj.plane[d]], crowd=True)


def _plane_qualities(obj, gt, ov, p, d, g, ig_box, rule):
    """The pair qualities of plane ``p``'s detections ``d`` (descending score) and instances
    ``g``: ``(iou, crowd)`` for AP, and ``(quality, crowd, threshold)`` of the rule (``None``
    when it is AP50's)."""
    if rule.iou_kind == "box" or gt.box_only[p] or not obj.has_masks:
        iou = box_iou(obj.box[d], gt.box[g])
        crowd = _box_crowd(obj, gt, d, ig_box)
    else:
        iou, crowd = ov.mask_iou(obj, gt, d, g)
    if rule.kind == "centroid":
        mostly_ignored = (crowd >= 0.5).astype(np.float64)  # COCO's crowd rule at 0.5
        return (iou, crowd), (_centroid_quality(obj, gt, d, g, rule), mostly_ignored, 1e-12)
    if rule.iou == COCO_IOUS[0]:
        return (iou, crowd), None
    return (iou, crowd), (iou, crowd, rule.iou)


def _greedy_planes(problems: list[tuple], thresholds: np.ndarray) -> list[np.ndarray]:
    """:func:`~torchsar.metrics.matching.greedy_match` of each ``(quality, crowd)`` problem,
    all at once: only the detections that can match or be ignored at the lowest threshold
    take part (the others are unmatched whatever the order), padded across problems."""
    thr = np.asarray(thresholds, dtype=np.float64)
    lowest = min(float(thr.min()), 1 - 1e-10)
    cands = [np.flatnonzero((q.max(axis=1, initial=-1.0) >= lowest) | (c >= lowest))
             for q, c in problems]  # fmt: skip
    n_d = max((c.size for c in cands), default=0)
    n_g = max((q.shape[1] for q, _ in problems), default=0)
    quality = np.full((len(problems), n_d, n_g), -1.0)
    crowd = np.full((len(problems), n_d), -1.0)
    for k, ((q, c), cand) in enumerate(zip(problems, cands, strict=True)):
        quality[k, : cand.size, : q.shape[1]] = q[cand]
        crowd[k, : cand.size] = c[cand]
    found = greedy_match_planes(quality, crowd, thr)
    out = []
    for k, ((q, _), cand) in enumerate(zip(problems, cands, strict=True)):
        res = np.full((thr.size, q.shape[0]), -1, dtype=np.int64)
        res[:, cand] = found[:, k, : cand.size]
        out.append(res)
    return out


def _match_multi_planes(obj, gt, ov, ig_box, rule, planes, out) -> None:
    """Match the detections of the planes with several instances (``planes``), writing
    into ``out = (ap, op, op_iou)``."""
    dets, gts = by_plane(obj.plane, obj.planes), by_plane(gt.plane, obj.planes)
    work = []
    for p in planes:
        d = dets[p]
        if d.size:
            d = d[np.argsort(-obj.score[d], kind="stable")]
            work.append((d, gts[p], *_plane_qualities(obj, gt, ov, p, d, gts[p], ig_box, rule)))
    if not work:
        return
    aps = _greedy_planes([w[2] for w in work], COCO_IOUS)
    ops = {}
    for thr in {w[3][2] for w in work if w[3] is not None}:
        chosen = [k for k, w in enumerate(work) if w[3] is not None and w[3][2] == thr]
        res = _greedy_planes([work[k][3][:2] for k in chosen], np.array([thr]))
        ops.update({k: r[0] for k, r in zip(chosen, res, strict=True)})
    for k, (d, g, (iou, _), _rule) in enumerate(work):
        a, o = aps[k], ops.get(k, aps[k][0])
        out[0][:, d] = np.where(a >= 0, g[np.maximum(a, 0)] if g.size else -1, a)
        out[1][d] = np.where(o >= 0, g[np.maximum(o, 0)] if g.size else -1, o)
        out[2][d] = np.where(o >= 0, iou[np.arange(d.size), np.maximum(o, 0)] if g.size else 0,
                             0.0)  # fmt: skip


def _boxes_only(rule: Matching, obj: Objects) -> bool:
    """Whether IoU is box IoU on every plane: the box rule, or objects without masks."""
    return rule.iou_kind == "box" or not obj.has_masks


def _single_quality(obj, gt, ov, ig_box, rule, d, g) -> tuple[np.ndarray, np.ndarray]:
    """IoU of each detection ``d`` with its plane's one instance ``g`` (-1: none, IoU NaN)
    and its crowd quality: box IoU under the box rule or on box-only planes, mask IoU
    otherwise."""
    p, has = obj.plane[d], g >= 0
    box = np.full(d.size, True) if _boxes_only(rule, obj) else gt.box_only[p]
    iou, crowd = np.full(d.size, np.nan), np.empty(d.size)
    for sel, boxes in ((box, True), (~box, False)):
        ds, hit = d[sel], sel & has
        if boxes:
            crowd[sel] = _box_crowd(obj, gt, ds, ig_box)
            iou[hit] = pair_box_iou(obj.box[d[hit]], gt.box[g[hit]])
        else:
            crowd[sel] = ov.crowd(obj, ds)
            iou[hit] = ov.pair_iou(obj, gt, d[hit], g[hit])
    return iou, crowd


def _match_single_planes(obj, gt, ov, ig_box, rule, single, out) -> None:
    """Match the detections of every plane with at most one instance (``single``) at once
    (:func:`~torchsar.metrics.matching.first_reach`), writing into ``out = (ap, op,
    op_iou)``."""
    d = np.flatnonzero(single[obj.plane])
    d = d[np.lexsort((-obj.score[d], obj.plane[d]))]  # by plane, then descending score
    if d.size == 0:
        return
    first_gt = np.full(obj.planes, -1)
    first_gt[gt.plane[::-1]] = np.arange(len(gt))[::-1]
    g = first_gt[obj.plane[d]]
    start = np.searchsorted(obj.plane[d], obj.plane[d], side="left")
    iou, crowd = _single_quality(obj, gt, ov, ig_box, rule, d, g)
    ap = first_reach(iou, crowd, COCO_IOUS, start)
    if rule.kind == "centroid":
        has = g >= 0
        quality = np.full(d.size, np.nan)
        quality[has] = _centroid_pairs(obj.centroid[d[has]], obj.box[d[has]], gt.box[g[has]], rule)
        op = first_reach(quality, (crowd >= 0.5).astype(np.float64), np.array([1e-12]), start)[0]
    elif rule.iou == COCO_IOUS[0]:
        op = ap[0]
    else:
        op = first_reach(iou, crowd, np.array([rule.iou]), start)[0]
    out[0][:, d] = np.where(ap == 0, g, ap)
    out[1][d] = np.where(op == 0, g, op)
    out[2][d] = np.where(op == 0, iou, 0.0)


def match_batch(obj: Objects, gt: GroundTruth, rule: Matching) -> BatchMatch:
    """Match every plane's objects to its instances (objects and instances of the same
    stack of planes). Planes with at most one instance (chips) are matched all at once, the
    others rank by rank across planes; the distance rule by
    :func:`torchsar.metrics.points.match_points`.
    """
    if rule.kind == "distance":
        from torchsar.metrics.points import match_points

        return match_points(obj, gt, rule)
    n_d, n_g = len(obj), len(gt)
    ap = np.full((len(COCO_IOUS), n_d), -1, dtype=np.int64)
    op = np.full(n_d, -1, dtype=np.int64)
    op_iou = np.zeros(n_d)
    ov = Overlaps(obj, gt)
    ig_box = gt.ignore_boxes
    single = np.bincount(gt.plane, minlength=obj.planes) <= 1
    _match_single_planes(obj, gt, ov, ig_box, rule, single, (ap, op, op_iou))
    _match_multi_planes(obj, gt, ov, ig_box, rule, np.flatnonzero(~single), (ap, op, op_iou))
    gt_det = np.full(n_g, -1, dtype=np.int64)
    hit = np.flatnonzero(op >= 0)
    gt_det[op[hit]] = hit
    gt_score = np.where(gt_det >= 0, obj.score[np.maximum(gt_det, 0)] if n_d else 0, -np.inf)
    kind = "iou" if obj.geometry != "point" else "none"
    return BatchMatch(ap, op, op_iou, gt_score, ov.touch.astype(np.int64), gt_det, kind)
