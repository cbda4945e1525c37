"""Every summary row says what it measured: the IoU of its AP (``iou_type``) and its matching
rule in words (``matching``); under the distance rule the AP is ``ap_distance``, never
``ap50``."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import torchsar_eval as te
from torchsar_eval.tables import headline_table


def _targets(masks: bool):
    m = torch.zeros(2, 32, 32, dtype=torch.bool)
    m[0, 2:10, 2:10] = True
    m[1, 20:28, 18:30] = True
    boxes = torch.tensor([[2.0, 2, 10, 10], [18, 20, 30, 28]])  # xyxy
    t = {"boxes": boxes, "labels": torch.tensor([1, 1]), "image_id": 0}
    return {**t, "masks": m} if masks else t


def _boxes():
    return {
        "boxes": torch.tensor([[2.0, 2, 10, 10], [18, 21, 30, 28], [0, 25, 5, 31]]),
        "scores": torch.tensor([0.9, 0.8, 0.3]),
        "labels": torch.tensor([1, 1, 1]),
    }


@pytest.mark.parametrize(
    ("masks", "pred_masks", "kind", "iou_type"),
    [
        (True, True, "mask", "mask"),
        (True, False, "mask", "box"),
        (False, False, "mask", "box"),
        (True, True, "box", "box"),
    ],
)
def test_the_iou_type_follows_what_was_compared(masks, pred_masks, kind, iou_type):
    ev = te.Evaluator("d", te.Scoring(matching=te.Matching(kind=kind), replicates=0))
    pred = _boxes()
    if pred_masks:
        pm = torch.zeros(3, 32, 32)
        for k, (x0, y0, x1, y1) in enumerate(pred["boxes"].int().tolist()):
            pm[k, y0:y1, x0:x1] = 1.0
        pred = {**pred, "masks": pm}
    ev.update([pred], [_targets(masks)])
    row = ev.compute().summary.iloc[0]
    assert row.iou_type == iou_type
    assert row.matching == f"{iou_type} IoU >= 0.5"
    assert math.isnan(row.ap_distance) and not math.isnan(row.ap50)


def test_mixed_targets_say_mask_and_box():
    ev = te.Evaluator("d", te.Scoring(replicates=0))
    pm = torch.zeros(3, 32, 32)
    pm[0, 2:10, 2:10] = pm[1, 20:28, 18:30] = 1.0
    ev.update([{**_boxes(), "masks": pm}], [_targets(True)])
    ev.update(
        [{**_boxes(), "masks": pm}],
        [{**_targets(False), "image_id": 1}],
        images=torch.zeros(1, 32, 32),
    )
    assert ev.iou_type == "mask+box"
    half = te.Evaluator("d", te.Scoring(replicates=0))
    half.update([{**_boxes(), "masks": pm}], [_targets(True)])
    other = te.Evaluator("d", te.Scoring(replicates=0))
    other.update(
        [{**_boxes(), "masks": pm}],
        [{**_targets(False), "image_id": 1}],
        images=torch.zeros(1, 32, 32),
    )
    merged = half + other
    assert merged.iou_type == "mask+box"
    back = te.Evaluator("d", te.Scoring(replicates=0))
    back.load_state_dict(merged.state_dict())
    assert back.iou_type == "mask+box"


def test_distance_rule_reports_ap_distance_not_ap50():
    rule = te.Matching(kind="distance", max_distance=3.0)
    evs = []
    for name, jitter in (("a", 0.0), ("b", 1.5)):
        ev = te.Evaluator(name, te.Scoring(matching=rule, replicates=50))
        for i in range(6):
            pts = torch.tensor([[5.0 + jitter, 5.0], [20.0, 20.0 + jitter], [28.0, 3.0]])
            ev.update(
                [{"points": pts, "scores": torch.tensor([0.9, 0.7, 0.2])}],
                [{"boxes": torch.tensor([[3.0, 3, 7, 7], [18, 18, 22, 22]]), "image_id": i}],
            )
        evs.append(ev)
    rows = [ev.compute().summary.iloc[0] for ev in evs]
    for row in rows:
        assert row.iou_type == "distance" and row.matching.startswith("distance < 3 px")
        assert math.isnan(row.ap50) and math.isnan(row.ap50_lo) and math.isnan(row.ap50_95)
        assert (
            0 < row.ap_distance <= 1 and row.ap_distance_lo <= row.ap_distance <= row.ap_distance_hi
        )
    head = headline_table(evs[0].compute().summary)
    assert "ap50" not in head.columns and "ap_distance" in head.columns


def test_paired_rows_name_the_distance_ap():
    from torchsar_eval.results import result_tables

    rule = te.Matching(kind="distance", max_distance=3.0)
    evs = []
    rng = np.random.default_rng(0)
    for name in ("a", "b"):
        ev = te.Evaluator(name, te.Scoring(matching=rule, replicates=30))
        for i in range(8):
            pts = torch.tensor([[5.0, 5.0], [20.0, 20.0]]) + torch.from_numpy(
                rng.normal(0, 1.5, (2, 2))
            )
            ev.update(
                [{"points": pts.float(), "scores": torch.tensor([0.9, 0.4])}],
                [{"boxes": torch.tensor([[3.0, 3, 7, 7], [18, 18, 22, 22]]), "image_id": i}],
            )
        evs.append(ev)
    paired = result_tables({"set": evs})["paired"]
    assert "ap_distance" in set(paired.metric) and "ap50" not in set(paired.metric)
