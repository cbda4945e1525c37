"""Ground truth as given, classes respected: on random COCO sets with float, overlapping
ground-truth boxes and masks, crowd regions, several categories, images without detections
and images with more than 100 detections, torchsar's AP equals ``pycocotools``' (the SAR
mode: no detection cap, per category or class-agnostic; AP by size too), and the
COCO-compatible state's ``eval['precision']`` and ``eval['recall']`` arrays equal
``COCOeval``'s entry for entry."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.reference.coco_sets import make_set, pycocotools_eval, torchsar_inputs
from torchsar.metrics import Matching, ObjectState, match_batch
from torchsar.metrics.object_state import ImageInfo

BIG = (1, 10, 100_000)  # pycocotools with no cap that matters: the SAR mode


def _state(gt, dets, iou_type, classes="auto"):
    rule = Matching(kind="mask" if iou_type == "segm" else "box", classes=classes)
    state = ObjectState(replicates=0)
    for truth, obj, orders in torchsar_inputs(gt, dets, iou_type):
        info = [ImageInfo(str(o), order=o) for o in orders]
        state.update(match_batch(obj, truth, rule), obj, truth, info)
    return state


def _ap(ev, area: int = 0) -> tuple[float, float]:
    """AP50 and AP50:95 of a COCOeval at the last cap and area range ``area``."""
    p = ev.eval["precision"][:, :, :, area, -1]  # (T, R, K)

    def mean(x):
        return float(x[x > -1].mean()) if (x > -1).any() else float("nan")

    return mean(p[0]), mean(p)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10**6),
    iou_type=st.sampled_from(["bbox", "segm"]),
    many=st.booleans(),
    ties=st.booleans(),
    classes=st.sampled_from(["auto", "agnostic"]),
)
def test_sar_ap_equals_pycocotools(seed, iou_type, many, ties, classes):
    # class-agnostic pycocotools (useCats=0) breaks ties in score within an image by
    # category id first; torchsar by the detections' order: tied scores only per class
    ties = ties and classes == "auto"
    gt, dets = make_set(seed, segm=iou_type == "segm", many=many, ties=ties)
    if iou_type == "segm":  # a mask's size is its own area (pycocotools reads a bbox's if any)
        dets = [{k: v for k, v in d.items() if k != "bbox"} for d in dets]
    ev = pycocotools_eval(gt, dets, iou_type, max_dets=BIG, use_cats=classes == "auto")
    state = _state(gt, dets, iou_type, classes)
    m = state.metrics()
    ap50, ap = _ap(ev)
    assert m["ap50"] == pytest.approx(ap50, abs=1e-9, nan_ok=True)
    assert m["ap50_95"] == pytest.approx(ap, abs=1e-9, nan_ok=True)
    for a, name in ((1, "small"), (2, "medium"), (3, "large")):
        assert m[f"ap_{name}"] == pytest.approx(_ap(ev, a)[1], abs=1e-9, nan_ok=True), name


def test_overlapping_boxes_stay_separate_targets():
    """Two ground-truth boxes that overlap, each hit by its own detection: both are true
    positives (painting them into one plane lost the lower one)."""
    gt = {
        "images": [{"id": 1, "file_name": "a", "height": 40, "width": 40}],
        "categories": [{"id": 1, "name": "ship"}],
        "annotations": [
            {
                "id": 1,
                "image_id": 1,
                "category_id": 1,
                "bbox": [5.0, 5.0, 20.0, 10.0],
                "area": 200.0,
                "iscrowd": 0,
            },
            {
                "id": 2,
                "image_id": 1,
                "category_id": 1,
                "bbox": [10.0, 8.0, 20.0, 10.0],
                "area": 200.0,
                "iscrowd": 0,
            },
        ],
    }
    dets = [
        {"image_id": 1, "category_id": 1, "bbox": [5.0, 5.0, 20.0, 10.0], "score": 0.9},
        {"image_id": 1, "category_id": 1, "bbox": [10.0, 8.0, 20.0, 10.0], "score": 0.8},
    ]
    m = _state(gt, dets, "bbox").metrics()
    assert (m["tp"], m["fp"]) == (2, 0) and m["ap50"] == pytest.approx(1.0)


def test_a_detection_of_the_wrong_class_is_a_false_alarm_unless_agnostic():
    gt = {
        "images": [{"id": 1, "file_name": "a", "height": 40, "width": 40}],
        "categories": [{"id": 1, "name": "ship"}, {"id": 2, "name": "tank"}],
        "annotations": [
            {
                "id": 1,
                "image_id": 1,
                "category_id": 1,
                "bbox": [5.0, 5.0, 20.0, 10.0],
                "area": 200.0,
                "iscrowd": 0,
            }
        ],
    }
    dets = [{"image_id": 1, "category_id": 2, "bbox": [5.0, 5.0, 20.0, 10.0], "score": 0.9}]
    per_class = _state(gt, dets, "bbox").metrics()
    agnostic = _state(gt, dets, "bbox", "agnostic").metrics()
    assert (per_class["tp"], per_class["fp"], per_class["ap50"]) == (0, 1, 0.0)
    assert (agnostic["tp"], agnostic["fp"]) == (1, 0) and agnostic["ap50"] == pytest.approx(1.0)


def test_crowd_regions_apply_to_their_class_only():
    """A detection on a crowd region of another class is a false alarm; on one of its own
    class (or class-agnostic matching) it is ignored."""
    gt = {
        "images": [{"id": 1, "file_name": "a", "height": 40, "width": 40}],
        "categories": [{"id": 1, "name": "ship"}, {"id": 2, "name": "tank"}],
        "annotations": [
            {
                "id": 1,
                "image_id": 1,
                "category_id": 2,
                "bbox": [0.0, 0.0, 20.0, 20.0],
                "area": 400.0,
                "iscrowd": 1,
            }
        ],
    }
    for cat, fp in ((1, 1), (2, 0)):
        dets = [{"image_id": 1, "category_id": cat, "bbox": [2.0, 2.0, 8.0, 8.0], "score": 0.9}]
        assert _state(gt, dets, "bbox").metrics()["fp"] == fp
        assert _state(gt, dets, "bbox", "agnostic").metrics()["fp"] == 0


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 10**6),
    iou_type=st.sampled_from(["bbox", "segm"]),
    many=st.booleans(),
    ties=st.booleans(),
)
def test_coco_compatible_arrays_equal_cocoeval(seed, iou_type, many, ties):
    """The whole ``eval['precision']`` and ``eval['recall']`` arrays (every IoU threshold,
    recall point, category, area range and cap), and the 12 stats."""
    from torchsar.metrics.coco_compat import CocoState
    from torchsar.metrics.coco_inputs import coco_images

    gt, dets = make_set(seed, segm=iou_type == "segm", many=many, ties=ties)
    ev = pycocotools_eval(gt, dets, iou_type)
    ids = {c["name"]: c["id"] for c in gt["categories"]}
    state = CocoState()
    for truth, obj, orders in torchsar_inputs(gt, dets, iou_type):
        state.update(coco_images(obj, truth, orders, iou_type, category_ids=ids))
    cats = sorted(ids.values())
    np.testing.assert_allclose(state.precision(cats), ev.eval["precision"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(state.recall(cats), ev.eval["recall"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(state.stats(), ev.stats, rtol=0, atol=1e-12)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10**6), iou_type=st.sampled_from(["bbox", "segm"]))
def test_per_class_ap_equals_pycocotools_per_category(seed, iou_type):
    from tests.reference.coco_sets import CATEGORIES

    gt, dets = make_set(seed, segm=iou_type == "segm")
    if iou_type == "segm":
        dets = [{k: v for k, v in d.items() if k != "bbox"} for d in dets]
    ev = pycocotools_eval(gt, dets, iou_type, max_dets=BIG)
    per_class = _state(gt, dets, iou_type).class_ap()
    p = ev.eval["precision"][:, :, :, 0, -1]  # (T, R, K): categories in id order
    for k, cat in enumerate(sorted(CATEGORIES, key=lambda c: c["id"])):
        x = p[:, :, k]
        if not (x > -1).any():
            assert cat["name"] not in per_class  # no target of the class
            continue
        ap50, ap = per_class[cat["name"]]
        assert ap50 == pytest.approx(float(x[0][x[0] > -1].mean()), abs=1e-9)
        assert ap == pytest.approx(float(x[x > -1].mean()), abs=1e-9)
    assert _state(gt, dets, iou_type, "agnostic").class_ap() == {}
