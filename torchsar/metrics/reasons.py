"""Why a target was missed and why a false alarm is one, in words, for the pictures of the
worst cases: the matching rule's verdict on the pair that came closest.

A missed target is either touched by no detection at the operating point ("no detection
touches it"), or the detections on it fail the rule: one matched another target, carries
another class, or its pair fails the rule's test (IoU below the threshold; under the
centroid rule a box too large or a centroid outside the grown target box; under the
distance rule, too far). A false alarm gets its error type
(:mod:`torchsar.metrics.error_types`) in words, and a ``localisation`` (a detection
overlapping one target but failing the rule) the rule's verdict on that pair.
"""

from __future__ import annotations

import numpy as np

from torchsar.metrics.assign import BatchMatch, touching_pairs
from torchsar.metrics.error_types import FA_TYPES, LOCALISATION
from torchsar.metrics.matching import GroundTruth, Matching, pair_box_iou
from torchsar.objects import Objects

__all__ = ["FA_WORDS", "false_alarm_reasons", "miss_reasons"]

FA_WORDS = {
    "merge": "covers several targets (merge)",
    "duplicate": "a second detection of a found target (duplicate)",
    "fragment": "a part of a target found by another detection (fragment)",
    "localisation": "overlaps a target but fails the rule",
    "shadow": "on a target's radar shadow",
    "clutter": "on clutter: touches no target",
}
"""Each false-alarm type in words."""


def _pair_iou(
    obj: Objects, gt: GroundTruth, d: np.ndarray, g: np.ndarray, inter: np.ndarray, rule: Matching
) -> tuple[np.ndarray, str]:
    """The IoU of each pair as the rule measures it (mask IoU where both sides have pixels and
    the rule reads masks, else box IoU), and which one it was."""
    iou = pair_box_iou(obj.box[d], gt.box[g])
    pixelled = np.diff(gt.masks.offsets)[g] > 0
    if rule.iou_kind != "mask" or not obj.has_masks or not pixelled.any():
        return iou, "box"
    union = obj.area[d].astype(np.float64) + gt.area[g] - inter
    mask_iou = np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)
    return np.where(pixelled, mask_iou, iou), "mask"


def _verdict(
    obj: Objects, gt: GroundTruth, d: int, g: int, iou: float, kind: str, rule: Matching
) -> str:
    """Why the pair ``(d, g)`` fails ``rule`` (an IoU or a centroid rule)."""
    if rule.kind == "centroid":
        db, gb = obj.box[d], gt.box[g]
        area = lambda b: max(float(b[2] - b[0]) * float(b[3] - b[1]), 1e-12)  # noqa: E731
        ratio = area(db) / area(gb)
        if ratio > rule.max_size_ratio:
            return f"the detection's box is {ratio:.1f}x the target's (> {rule.max_size_ratio:g}x)"
        grow = rule.margin * max(float(gb[2] - gb[0]), float(gb[3] - gb[1]))
        return f"the detection's centroid lies outside the target box grown by {grow:.1f} px"
    return f"best {kind} IoU {iou:.2f} < {rule.iou:g}"


def miss_reasons(
    m: BatchMatch,
    obj: Objects,
    gt: GroundTruth,
    rule: Matching,
    counted: np.ndarray,
    which: np.ndarray,
) -> list[str]:
    """Why each target ``which[i]`` was missed, given the detections ``counted`` at the
    operating point (bools over ``obj``) and the batch's matches ``m`` under ``rule``."""
    if rule.kind == "distance":
        return [_far(obj, gt, rule, counted, int(g)) for g in which]
    d, g, inter = touching_pairs(obj, gt)
    keep = counted[d] & np.isin(g, which)
    d, g, inter = d[keep], g[keep], inter[keep]
    iou, kind = _pair_iou(obj, gt, d, g, inter, rule)
    out = []
    for t in which:
        on = np.flatnonzero(g == t)
        if on.size == 0:
            out.append("no detection touches it")
            continue
        dets = d[on]
        other = (m.op[dets] >= 0) & (m.op[dets] != t)
        if m.by_class and obj.classes is not None:
            same = np.array([obj.classes[k] == gt.classes[t] for k in dets])
            if not same.any():
                out.append(f"the detection on it is labelled {obj.classes[dets[0]]!s}")
                continue
            on, dets, other = on[same], dets[same], other[same]
        if other.all():
            out.append("the detection on it matched another target")
            continue
        best = on[~other][np.argmax(iou[on[~other]])]
        out.append(_verdict(obj, gt, int(d[best]), int(t), float(iou[best]), kind, rule))
    return out


def _far(obj: Objects, gt: GroundTruth, rule: Matching, counted: np.ndarray, t: int) -> str:
    """Under the distance rule: how far the nearest counted detection was."""
    p = int(gt.plane[t])
    near = np.flatnonzero(counted & (obj.plane == p))
    if near.size == 0 or gt.centroid is None:
        return "no detection in the image"
    delta = obj.centroid[near] - gt.centroid[t]
    if rule.distance_units == "m" and gt.spacing is not None and np.isfinite(gt.spacing[p]).all():
        delta = delta * gt.spacing[p]
    dist = float(np.sqrt((delta**2).sum(axis=1)).min())
    return (
        f"nearest detection {dist:.1f} {rule.distance_units} away (tolerance {rule.max_distance:g})"
    )


def false_alarm_reasons(
    types: np.ndarray,
    m: BatchMatch,
    obj: Objects,
    gt: GroundTruth,
    rule: Matching,
    which: np.ndarray,
) -> list[str]:
    """Each false alarm ``which[i]`` in words: its type (``types``: per detection, an index of
    :data:`~torchsar.metrics.error_types.FA_TYPES`), and for a localisation the rule's
    verdict on the target it overlaps."""
    out = [FA_WORDS[FA_TYPES[int(types[k])]] if types[k] >= 0 else "unmatched" for k in which]
    local = [i for i, k in enumerate(which) if types[k] == LOCALISATION]
    if not local or rule.kind == "distance":
        return out
    d, g, inter = touching_pairs(obj, gt)
    iou, kind = _pair_iou(obj, gt, d, g, inter, rule)
    for i in local:
        k = which[i]
        on = np.flatnonzero(d == k)
        if on.size:
            best = on[np.argmax(iou[on])]
            out[i] += ": " + _verdict(obj, gt, int(k), int(g[best]), float(iou[best]), kind, rule)
    return out
