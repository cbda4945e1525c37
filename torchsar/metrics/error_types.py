"""What each false alarm is: SAR detection error types, one per false alarm.

A false alarm is a detection the matching rule left unmatched (not one it ignored on a
don't-care region). A detection *touches* a target when they share a pixel (objects with
masks), when their boxes intersect (boxes), or when the point's pixel lies on the target
(points); under the distance rule, when it is closer than the tolerance. Each false alarm
gets the first type that applies, in this order:

1. ``merge``: it touches two or more targets (one detection covering several targets).
2. ``duplicate``: it touches one target, already matched by a detection ranked before it
   (higher score; equal scores: the earlier object), and covers at least half of that
   target (:data:`WHOLE` of its pixels; for boxes and box-only targets, of its box): a
   second whole detection of the target.
3. ``fragment``: it touches one target already matched by a detection ranked before it,
   and covers less than half of it: a part of the target.
4. ``localisation``: it touches one target not matched before it: it overlaps the target
   but fails the matching rule (misplaced, too large or too small).
5. ``shadow``: it touches no target and covers at least one pixel of a target's radar
   shadow (planes whose ignore pixels are declared shadow:
   :attr:`~torchsar.metrics.matching.GroundTruth.shadow`; elsewhere this type is 0).
6. ``clutter``: everything else (background clutter).

"Matched before" only looks at detections ranked above the false alarm, which are present
whenever it is (a global score threshold keeps a prefix of the ranking), so a type does not
depend on the operating point: the object state keeps each detection's type and reads the
counts at any operating point. Under the distance rule a point cannot cover or split a
target: a false alarm within the tolerance of a target (which was then matched to another
detection) is a ``duplicate``, the others are ``shadow`` or ``clutter``.
"""

from __future__ import annotations

import numpy as np

from torchsar.metrics.assign import BatchMatch, by_plane, point_pixels, touching_pairs
from torchsar.metrics.matching import GroundTruth, Matching, pair_box_iou
from torchsar.objects import Objects

__all__ = ["FA_TYPES", "WHOLE", "false_alarm_types"]

FA_TYPES = ("merge", "duplicate", "fragment", "localisation", "shadow", "clutter")
"""False-alarm types in priority order (see the module docstring)."""
MERGE, DUPLICATE, FRAGMENT, LOCALISATION, SHADOW, CLUTTER = range(len(FA_TYPES))
WHOLE = 0.5
"""The share of a target a second detection covers to be a ``duplicate`` (else a
``fragment``)."""


def _coverage(obj: Objects, gt: GroundTruth, d, g, inter) -> np.ndarray:
    """The share of target ``g[i]`` that detection ``d[i]`` covers: of its pixels (objects
    with masks on targets with pixels), else of its box (boxes, box targets given without
    pixels; points cover nothing)."""
    by_box = pair_box_iou(gt.box[g], obj.box[d], crowd=True)  # intersection / target box
    if not obj.has_masks:
        return by_box
    pixelled = np.diff(gt.masks.offsets)[g] > 0
    return np.where(pixelled, inter / np.maximum(gt.area[g], 1), by_box)


def _near_pairs(obj: Objects, gt: GroundTruth, rule: Matching) -> tuple[np.ndarray, np.ndarray]:
    """Pairs closer than the distance rule's tolerance (in its units)."""
    from torchsar.metrics.distance import pair_distances
    from torchsar.metrics.points import _spacing

    dets, gts = by_plane(obj.plane, obj.planes), by_plane(gt.plane, obj.planes)
    centroid = gt.centroid if gt.centroid is not None else np.zeros((len(gt), 2))
    out_d, out_g = [], []
    for p in range(obj.planes):
        d, g = dets[p], gts[p]
        if d.size and g.size:
            near = pair_distances(obj.centroid[d], centroid[g], _spacing(gt, p, rule))
            i, j = np.nonzero(near < float(rule.max_distance))
            out_d.append(d[i])
            out_g.append(g[j])
    if not out_d:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(out_d), np.concatenate(out_g)


def _on_shadow(obj: Objects, gt: GroundTruth, cand: np.ndarray) -> np.ndarray:
    """Whether each detection ``cand[i]`` covers a shadow pixel."""
    out = np.zeros(cand.size, bool)
    if gt.shadow is None or not gt.shadow.any() or cand.size == 0:
        return out
    shadow = gt.ignore & gt.shadow[:, None, None]
    if obj.has_masks:
        owner, idx = obj.pixel_lists()
        hit = np.zeros(len(obj), bool)
        hit[owner[shadow.reshape(-1)[idx]]] = True
        return hit[cand]
    if obj.geometry == "point":
        return shadow.reshape(-1)[point_pixels(obj)[cand]]
    h, w = obj.shape
    for i, k in enumerate(cand):
        p = int(obj.plane[k])
        if gt.shadow[p]:
            r0, c0, r1, c1 = (int(np.floor(v + 0.5)) for v in obj.box[k])
            out[i] = bool(
                shadow[
                    p, max(r0, 0) : min(max(r1, r0 + 1), h), max(c0, 0) : min(max(c1, c0 + 1), w)
                ].any()
            )
    return out


def false_alarm_types(m: BatchMatch, obj: Objects, gt: GroundTruth, rule: Matching) -> np.ndarray:
    """The type of each detection: an index into :data:`FA_TYPES` for a false alarm, -1 for
    a detection that matched a target or was ignored (see the module docstring).

    Args:
        m: the batch's matches under ``rule`` (:func:`~torchsar.metrics.match_batch`).
        obj, gt: its objects and ground truth.
        rule: the matching rule ``m`` was made with.

    Returns:
        int64 ``(M,)``.
    """
    n = len(obj)
    out = np.full(n, -1, np.int64)
    fa = np.flatnonzero(m.op == -1)
    if fa.size == 0:
        return out
    if rule.kind == "distance":
        d, _ = _near_pairs(obj, gt, rule)
        near = np.bincount(d, minlength=n)[fa] > 0
        out[fa[near]] = DUPLICATE
        rest = fa[~near]
    else:
        d, g, inter = touching_pairs(obj, gt)
        touches = np.bincount(d, minlength=n)
        out[fa[touches[fa] >= 2]] = MERGE
        single = (touches[d] == 1) & (m.op[d] == -1)
        d, g, inter = d[single], g[single], inter[single]
        e = m.gt_det[g]  # the detection that matched the touched target (-1: none)
        es = obj.score[np.maximum(e, 0)]
        before = (e >= 0) & ((es > obj.score[d]) | ((es == obj.score[d]) & (e < d)))
        whole = _coverage(obj, gt, d, g, inter) >= WHOLE
        out[d] = np.where(before, np.where(whole, DUPLICATE, FRAGMENT), LOCALISATION)
        rest = fa[touches[fa] == 0]
    out[rest] = np.where(_on_shadow(obj, gt, rest), SHADOW, CLUTTER)
    return out
