"""False-alarm types on hand-made masks: one case of each type, the priority order, the
independence from the operating point, and on simulated data every false alarm counted
exactly once."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import torchsar as ts
import torchsar_eval as te
from torchsar.metrics import ImageInfo, Matching, ObjectState, ground_truth, match_batch
from torchsar.metrics.error_types import FA_TYPES, false_alarm_types
from torchsar.objects import Objects

H = W = 64
TARGETS = {  # (r0, r1, c0, c1), end-exclusive
    "A": (5, 15, 5, 15),
    "B": (5, 15, 30, 40),
    "C": (5, 15, 43, 53),
    "D": (30, 40, 5, 15),  # missed
    "E": (30, 40, 30, 40),
}
SHADOW = (50, 60, 5, 21)
DETECTIONS = [  # (name, box, score, expected type or None for a match)
    ("hit A", (5, 15, 5, 15), 0.9, None),
    ("second whole A", (5, 14, 5, 15), 0.8, "duplicate"),  # 90 % of A
    ("part of A", (5, 8, 5, 8), 0.7, "fragment"),  # 9 % of A
    ("over B and C", (5, 15, 30, 53), 0.6, "merge"),  # IoU < 0.5 with either
    ("beside E", (30, 40, 36, 46), 0.5, "localisation"),  # IoU 40 / 160 with E
    ("edge of shadow", (58, 63, 10, 13), 0.4, "shadow"),  # 6 of 15 px on the shadow
    ("in clutter", (20, 25, 55, 60), 0.3, "clutter"),
]


def _truth(shadow: bool = True):
    inst = np.zeros((1, H, W), np.int64)
    for k, (r0, r1, c0, c1) in enumerate(TARGETS.values(), start=1):
        inst[0, r0:r1, c0:c1] = k
    ignore = np.zeros((1, H, W), bool)
    r0, r1, c0, c1 = SHADOW
    ignore[0, r0:r1, c0:c1] = True
    return ground_truth(inst, ignore, shadow=np.array([shadow]))


def _objects(geometry: str, dets=DETECTIONS) -> Objects:
    score = np.array([d[2] for d in dets])
    if geometry == "box":
        boxes = np.array([[r0, c0, r1, c1] for _, (r0, r1, c0, c1), _, _ in dets], float)
        return Objects.from_boxes(boxes, score, shape=(H, W), threshold=0.0)
    masks = np.zeros((len(dets), H, W), bool)
    for i, (_, (r0, r1, c0, c1), _, _) in enumerate(dets):
        masks[i, r0:r1, c0:c1] = True
    return Objects.from_masks(masks, score, threshold=0.0)


@pytest.mark.parametrize("geometry,rule", [("mask", Matching("mask")), ("box", Matching("box"))])
def test_one_false_alarm_of_each_type(geometry, rule):
    gt, obj = _truth(), _objects(geometry)
    m = match_batch(obj, gt, rule)
    types = false_alarm_types(m, obj, gt, rule)
    got = {
        name: None if t < 0 else FA_TYPES[t]
        for (name, *_), t in zip(DETECTIONS, types.tolist(), strict=True)
    }
    assert got == {name: want for name, _, _, want in DETECTIONS}
    assert list(m.op).count(-1) == len(DETECTIONS) - 1  # every other detection is a false alarm


def test_without_shadow_masks_the_shadow_type_is_clutter():
    gt, obj = _truth(shadow=False), _objects("mask")
    rule = Matching("mask")
    types = false_alarm_types(match_batch(obj, gt, rule), obj, gt, rule)
    assert FA_TYPES[types[5]] == "clutter" and "shadow" not in [
        FA_TYPES[t] for t in types if t >= 0
    ]


def test_ranked_before_decides_not_the_operating_point():
    """A part of A scoring above the detection that matches A is a localisation error (A was
    not matched before it), and stays one at any threshold: the counts are nested."""
    dets = [("part", (5, 8, 5, 8), 0.9, "localisation"), ("whole", (5, 15, 5, 15), 0.5, None)]
    gt, obj, rule = _truth(), _objects("mask", dets), Matching("mask")
    m = match_batch(obj, gt, rule)
    types = false_alarm_types(m, obj, gt, rule)
    assert types.tolist() == [FA_TYPES.index("localisation"), -1]
    state = ObjectState(replicates=0)
    state.update(m, obj, gt, [ImageInfo("a")], fa_types=types)
    loc = FA_TYPES.index("localisation")
    assert state.fa_types(0.6)[loc] == 1 and state.fa_types(0.95)[loc] == 0


def test_priority_merge_before_fragment():
    """A detection touching A (already matched) and B is a merge, not a fragment."""
    dets = [("hit A", (5, 15, 5, 15), 0.9, None), ("A and B", (8, 10, 14, 31), 0.5, "merge")]
    gt, obj, rule = _truth(), _objects("mask", dets), Matching("mask")
    types = false_alarm_types(match_batch(obj, gt, rule), obj, gt, rule)
    assert types.tolist() == [-1, FA_TYPES.index("merge")]


def test_distance_rule_duplicates():
    """Points: the second point within the tolerance of a matched target is a duplicate."""
    gt = _truth()
    pts = np.array([[9.5, 9.5], [10.5, 9.0], [22.0, 57.0]])
    obj = Objects.from_points(pts, np.array([0.9, 0.8, 0.7]), shape=(H, W), threshold=0.0)
    rule = Matching("distance", max_distance=3.0)
    types = false_alarm_types(match_batch(obj, gt, rule), obj, gt, rule)
    assert types.tolist() == [-1, FA_TYPES.index("duplicate"), FA_TYPES.index("clutter")]


class Scenes(torch.utils.data.Dataset):
    def __init__(self, n: int) -> None:
        self.n = n

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, i: int) -> dict:
        item = ts.simulate.scenes(
            1, size=192, n_targets=(6, 12), building_px=(30, 40), seed=5, start=i
        )[0]
        item["meta"] = {"name": f"s{i}", **item["meta"]}
        return item


def test_every_false_alarm_and_miss_is_counted_once_on_simulated_scenes():
    res = te.evaluate(
        {"scenes": Scenes(3)}, ["ca", "so"], scoring=te.Scoring(replicates=0), progress=False
    )
    e = res.errors
    s = res.summary.set_index("detector")
    for det in ("ca", "so"):
        mine = e[e.detector == det]
        fa = mine[mine.error == "false_alarm"]
        assert list(fa.type) == list(FA_TYPES)
        assert fa["count"].sum() == s.loc[det, "fp"]
        for prefix in ("size:", "scr:", "scr_known:"):
            miss = mine[(mine.error == "miss") & mine.type.str.startswith(prefix)]
            assert miss["count"].sum() == s.loc[det, "fn"], prefix
    assert e[(e.error == "false_alarm") & (e.type != "clutter")]["count"].sum() > 0
