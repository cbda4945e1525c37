"""Why a target was missed and why a false alarm is one: the rule's verdict, in words,
checked on hand-made cases whose answer is known."""

from __future__ import annotations

import numpy as np

from torchsar.metrics import Matching, match_batch
from torchsar.metrics.error_types import false_alarm_types
from torchsar.metrics.reasons import FA_WORDS, false_alarm_reasons, miss_reasons
from torchsar.metrics.truth import ground_truth
from torchsar.objects import Objects


def _truth():
    """Three 10 x 10 targets on a 64 x 64 plane."""
    inst = np.zeros((1, 64, 64), np.int32)
    inst[0, 5:15, 5:15] = 1
    inst[0, 30:40, 30:40] = 2
    inst[0, 50:60, 5:15] = 3
    return ground_truth(inst)


def _boxes(boxes, scores):
    return Objects.from_boxes(
        np.array(boxes, float),
        np.array(scores, float),
        shape=(64, 64),
        plane=np.zeros(len(boxes), np.int64),
        planes=1,
    )


def test_miss_reasons_under_an_iou_rule():
    gt = _truth()
    # target 1 hit exactly; target 2 touched by a shifted box (IoU 25/175); target 3 untouched
    obj = _boxes([[5, 5, 15, 15], [35, 35, 45, 45]], [0.9, 0.8])
    rule = Matching(kind="box")
    m = match_batch(obj, gt, rule)
    counted = np.ones(len(obj), bool)
    why = miss_reasons(m, obj, gt, rule, counted, np.array([1, 2]))
    assert why == [f"best box IoU {25 / 175:.2f} < 0.5", "no detection touches it"]


def test_a_detection_matched_elsewhere_is_named():
    gt = _truth()
    obj = _boxes([[5, 5, 40, 40]], [0.9])  # one big box over targets 1 and 2
    rule = Matching(kind="centroid", max_size_ratio=100.0, margin=10.0)
    m = match_batch(obj, gt, rule)
    assert (m.op >= 0).sum() == 1
    missed = np.flatnonzero(m.gt_det[:2] < 0)
    why = miss_reasons(m, obj, gt, rule, np.ones(1, bool), missed)
    assert why == ["the detection on it matched another target"]


def test_centroid_rule_names_the_oversized_box():
    gt = _truth()
    obj = _boxes([[28, 28, 60, 60]], [0.9])  # covers target 2, 10x its area
    rule = Matching(kind="centroid")
    m = match_batch(obj, gt, rule)
    why = miss_reasons(m, obj, gt, rule, np.ones(1, bool), np.array([1]))
    assert why == ["the detection's box is 10.2x the target's (> 4x)"]


def test_detections_below_the_operating_point_do_not_count():
    gt = _truth()
    obj = _boxes([[30, 30, 40, 40]], [0.1])
    rule = Matching(kind="box")
    m = match_batch(obj, gt, rule)
    assert miss_reasons(m, obj, gt, rule, np.zeros(1, bool), np.array([1])) == [
        "no detection touches it"
    ]


def test_false_alarm_reasons_give_the_type_and_the_verdict():
    gt = _truth()
    obj = _boxes([[5, 5, 15, 15], [20, 50, 26, 56], [33, 33, 43, 43]], [0.9, 0.8, 0.7])
    rule = Matching(kind="box")
    m = match_batch(obj, gt, rule)
    types = false_alarm_types(m, obj, gt, rule)
    why = false_alarm_reasons(types, m, obj, gt, rule, np.array([1, 2]))
    assert why[0] == FA_WORDS["clutter"]
    iou = 49 / (100 + 100 - 49)
    assert why[1] == f"{FA_WORDS['localisation']}: best box IoU {iou:.2f} < 0.5"
