"""Match a batch of objects to its ground truth by the distance between their centroids
(:class:`~torchsar.metrics.Matching` with ``kind="distance"``), plane by plane.

- AP and the FROC: detections visited in descending score order, each taking the nearest
  free instance closer than the tolerance (:func:`~torchsar.metrics.distance.greedy_match_by_score`;
  nested by score, so one pass gives every point of the curves).
- The operating point (``assign="optimal"``): the detections at the operating point (score
  above the objects' threshold, or all when none is declared) are assigned optimally, as
  the xView3-SAR metric does (the most pairs within the tolerance, then the least total
  distance: :func:`~torchsar.metrics.distance.optimal_match`); the weaker detections then
  take the instances left, greedily by score. ``assign="greedy"``: the greedy visit.
- Don't care: a detection left unmatched that lies closer than the tolerance to an ignore
  pixel is neither a true nor a false positive (:func:`~torchsar.metrics.distance.dont_care`).

Distances are in pixels, or in metres with each image's pixel spacing (``(row, col)``,
possibly anisotropic). Instances are points at their centroid (the box centre for box-only
ground truth); objects at theirs.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from torchsar.errors import OptionError
from torchsar.metrics.batch import BatchMatch, by_plane
from torchsar.metrics.distance import (
    dont_care,
    greedy_match_by_score,
    optimal_match,
    pair_distances,
)
from torchsar.metrics.matching import COCO_IOUS, GroundTruth, Matching
from torchsar.objects import Objects

__all__ = ["match_points"]


def _spacing(gt: GroundTruth, p: int, rule: Matching) -> tuple[float, float] | None:
    if rule.distance_units == "px":
        return None
    sp = gt.spacing[p] if gt.spacing is not None else np.full(2, np.nan)
    if not np.isfinite(sp).all():
        raise OptionError(
            "distances in metres need the pixel spacing of every image; one "
            "has none (declare it, or give max_distance in pixels)"
        )
    return float(sp[0]), float(sp[1])


def _ignore_distance(ignore: np.ndarray, points: np.ndarray, spacing) -> np.ndarray:
    """Distance from each point to the nearest ignore pixel of the plane (inf: none)."""
    if not ignore.any() or points.size == 0:
        return np.full(points.shape[0], np.inf)
    h, w = ignore.shape
    dist = ndimage.distance_transform_edt(~ignore, sampling=spacing)
    r = np.clip(np.floor(points[:, 0] + 0.5), 0, h - 1).astype(np.int64)
    c = np.clip(np.floor(points[:, 1] + 0.5), 0, w - 1).astype(np.int64)
    return dist[r, c]


def _operating(obj: Objects) -> np.ndarray:
    """Which objects are at the operating point."""
    if obj.threshold is None:
        return np.ones(len(obj), bool)
    return obj.score > obj.threshold


def _optimal_then_greedy(dist, score, top, tol) -> np.ndarray:
    """Optimal assignment of the detections ``top``; the rest take what is left, greedily."""
    out = np.full(dist.shape[0], -1, dtype=np.int64)
    t = np.flatnonzero(top)
    out[t] = optimal_match(dist[t], tol)
    free = np.setdiff1d(np.arange(dist.shape[1]), out[t][out[t] >= 0])
    rest = np.flatnonzero(~top)
    if rest.size and free.size:
        local = greedy_match_by_score(dist[np.ix_(rest, free)], score[rest], tol)
        out[rest] = np.where(local >= 0, free[np.maximum(local, 0)], -1)
    return out


def match_points(obj: Objects, gt: GroundTruth, rule: Matching) -> BatchMatch:
    """Match every plane's objects to its instances by centroid distance (see the module
    docstring). ``BatchMatch.ap`` holds the greedy statuses (the same at every IoU row; one
    area range: a point has no area)."""
    n_d, n_g = len(obj), len(gt)
    ap = np.full((1, len(COCO_IOUS), n_d), -1, dtype=np.int64)
    op = np.full(n_d, -1, dtype=np.int64)
    touch = np.zeros(n_g, np.int64)
    tol = float(rule.max_distance)
    top = _operating(obj)
    dets, gts = by_plane(obj.plane, obj.planes), by_plane(gt.plane, obj.planes)
    centroid = gt.centroid if gt.centroid is not None else np.zeros((n_g, 2))
    for p in range(obj.planes):
        d, g = dets[p], gts[p]
        if d.size == 0:
            continue
        d = d[np.argsort(-obj.score[d], kind="stable")]
        sp = _spacing(gt, p, rule)
        dist = pair_distances(obj.centroid[d], centroid[g], sp)
        near = _ignore_distance(gt.ignore[p], obj.centroid[d], sp)
        greedy = greedy_match_by_score(dist, obj.score[d], tol)
        chosen = (
            greedy
            if rule.assign == "greedy"
            else _optimal_then_greedy(dist, obj.score[d], top[d], tol)
        )
        for local, into in ((greedy, ap), (chosen, op)):
            status = np.where(local >= 0, g[np.maximum(local, 0)] if g.size else -1, -1)
            status[dont_care(obj.centroid[d], local, near, tol)] = -2
            into[..., d] = status
        touch[g] += (dist < tol).sum(axis=0)
    gt_det = np.full(n_g, -1, dtype=np.int64)
    hit = np.flatnonzero(op >= 0)
    gt_det[op[hit]] = hit
    gt_score = np.where(gt_det >= 0, obj.score[np.maximum(gt_det, 0)] if n_d else 0, -np.inf)
    return BatchMatch(ap, op, np.zeros(n_d), gt_score, touch, gt_det, ap_kind="distance")
