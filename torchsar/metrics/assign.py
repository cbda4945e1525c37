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
    greedy_match,
    mask_overlaps,
)
from torchsar.objects import Objects

__all__ = ["BatchMatch", "match_batch"]


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
        overlaps: int ``(G,)`` number of detections touching each instance (fragmentation).
    """

    ap: np.ndarray
    op: np.ndarray
    op_iou: np.ndarray
    gt_score: np.ndarray
    overlaps: np.ndarray


def _by_plane(plane: np.ndarray, n_planes: int) -> list[np.ndarray]:
    order = np.argsort(plane, kind="stable")
    cuts = np.searchsorted(plane[order], np.arange(n_planes + 1))
    return [order[cuts[p] : cuts[p + 1]] for p in range(n_planes)]


def _ignore_boxes(ignore: np.ndarray) -> np.ndarray:
    """Bounding box of each plane's ignore pixels ``(N, 4)`` (zero box when none)."""
    rows, cols = ignore.any(axis=2), ignore.any(axis=1)
    out = np.zeros((ignore.shape[0], 4))
    for p in np.flatnonzero(rows.any(axis=1)):
        r, c = np.flatnonzero(rows[p]), np.flatnonzero(cols[p])
        out[p] = (r[0], c[0], r[-1] + 1, c[-1] + 1)
    return out


def _centroid_quality(obj: Objects, gt: GroundTruth, d: np.ndarray, g: np.ndarray, m: Matching):
    """Prescreening pair quality ``1 / (1 + distance to the box centre)``, 0 where the
    centroid is outside the grown box or the detection box is too large."""
    cen = obj.centroid[d][:, None, :] + 0.5  # pixel centres, in box coordinates
    box = gt.box[g][None, :, :]
    grow = m.margin * np.maximum(box[..., 2] - box[..., 0], box[..., 3] - box[..., 1])
    inside = (
        (cen[..., 0] >= box[..., 0] - grow)
        & (cen[..., 0] <= box[..., 2] + grow)
        & (cen[..., 1] >= box[..., 1] - grow)
        & (cen[..., 1] <= box[..., 3] + grow)
    )
    db, gb = obj.box[d], gt.box[g]
    area_d = ((db[:, 2] - db[:, 0]) * (db[:, 3] - db[:, 1]))[:, None]
    area_g = ((gb[:, 2] - gb[:, 0]) * (gb[:, 3] - gb[:, 1]))[None, :]
    ok = inside & (area_d <= m.max_size_ratio * area_g)
    mid = 0.5 * (box[..., :2] + box[..., 2:])
    dist = np.hypot(*(cen - mid).transpose(2, 0, 1))
    return np.where(ok, 1.0 / (1.0 + dist), 0.0)


class _Overlaps:
    """Pixel intersections of the batch's objects with its instances and ignore pixels."""

    def __init__(self, obj: Objects, gt: GroundTruth) -> None:
        n_d, n_g = len(obj), len(gt)
        self.d, self.g, self.inter = mask_overlaps(obj.labels, n_d, gt.ids, n_g)
        lab = obj.labels.reshape(-1)
        self.ignored = np.bincount(lab[gt.ignore.reshape(-1)], minlength=n_d + 1)[1:]
        self.touch = np.bincount(self.g, minlength=n_g)

    def mask_iou(self, obj: Objects, gt: GroundTruth, d: np.ndarray, g: np.ndarray):
        pos_d = np.full(len(obj), -1)
        pos_d[d] = np.arange(d.size)
        pos_g = np.full(len(gt), -1)
        pos_g[g] = np.arange(g.size)
        sel = (pos_d[self.d] >= 0) & (pos_g[self.g] >= 0)
        dd, gg, inter = self.d[sel], self.g[sel], self.inter[sel]
        iou = np.zeros((d.size, g.size))
        iou[pos_d[dd], pos_g[gg]] = inter / (obj.area[dd] + gt.area[gg] - inter)
        crowd = self.ignored[d] / np.maximum(obj.area[d], 1)
        return iou, crowd


def _plane_match(obj, gt, ov, p, d, g, ig_box, rule):
    """Assign the detections ``d`` (descending score) of plane ``p`` to its instances ``g``."""
    if rule.iou_kind == "box" or gt.box_only[p]:
        iou = box_iou(obj.box[d], gt.box[g])
        crowd = box_iou(obj.box[d], ig_box[p][None], crowd=True)[:, 0]
    else:
        iou, crowd = ov.mask_iou(obj, gt, d, g)
    ap = greedy_match(iou, crowd, COCO_IOUS)
    if rule.kind == "centroid":
        quality = _centroid_quality(obj, gt, d, g, rule)
        mostly_ignored = (crowd >= 0.5).astype(np.float64)  # COCO's crowd rule at 0.5
        op = greedy_match(quality, mostly_ignored, np.array([1e-12]))[0]
    elif rule.iou == COCO_IOUS[0]:
        op = ap[0]
    else:
        op = greedy_match(iou, crowd, np.array([rule.iou]))[0]
    op_iou = np.where(op >= 0, iou[np.arange(d.size), np.maximum(op, 0)] if g.size else 0, 0.0)
    return ap, op, op_iou


def match_batch(obj: Objects, gt: GroundTruth, rule: Matching) -> BatchMatch:
    """Match every plane's objects to its instances (objects and instances of the same
    stack of planes)."""
    n_d, n_g = len(obj), len(gt)
    ap = np.full((len(COCO_IOUS), n_d), -1, dtype=np.int64)
    op = np.full(n_d, -1, dtype=np.int64)
    op_iou = np.zeros(n_d)
    ov = _Overlaps(obj, gt)
    ig_box = _ignore_boxes(gt.ignore)
    dets, gts = _by_plane(obj.plane, obj.planes), _by_plane(gt.plane, obj.planes)
    for p in range(obj.planes):
        d, g = dets[p], gts[p]
        if d.size == 0:
            continue
        d = d[np.argsort(-obj.score[d], kind="stable")]
        a, o, oi = _plane_match(obj, gt, ov, p, d, g, ig_box, rule)
        ap[:, d] = np.where(a >= 0, g[np.maximum(a, 0)] if g.size else -1, a)
        op[d] = np.where(o >= 0, g[np.maximum(o, 0)] if g.size else -1, o)
        op_iou[d] = oi
    gt_score = np.full(n_g, -np.inf)
    hit = op >= 0
    gt_score[op[hit]] = obj.score[hit]
    return BatchMatch(ap, op, op_iou, gt_score, ov.touch.astype(np.int64))
