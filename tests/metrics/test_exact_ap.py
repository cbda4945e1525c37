"""Exact AP: AP50 and AP50:95 equal pycocotools (``useCats=0``, no detection cap) on random
predictions with continuous scores in [0, 1] (ties included), overlapping boxes and masks,
images without predictions and images with more than 100, whatever the split into batches."""

from __future__ import annotations

import contextlib
import io
import itertools

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from torchsar.metrics import Matching, ObjectState, ground_truth, match_batch
from torchsar.metrics.object_state import ImageInfo
from torchsar.objects import Objects
from torchsar_eval.coco import CocoExport

SIZE = 48


def _truth(rng: np.random.Generator, n_img: int):
    inst = np.zeros((n_img, SIZE, SIZE), np.int32)
    ignore = np.zeros((n_img, SIZE, SIZE), bool)
    for p in range(n_img):
        for i in range(1, int(rng.integers(0, 6)) + 1):
            r, c = rng.integers(0, SIZE - 12, 2)
            inst[p, r : r + rng.integers(3, 12), c : c + rng.integers(3, 12)] = i
        if rng.random() < 0.4:
            r, c = rng.integers(0, SIZE - 10, 2)
            if not inst[p, r : r + 8, c : c + 8].any():  # a whole square: pycocotools' bbox
                ignore[p, r : r + 8, c : c + 8] = True  # crowd rule reads its box, we its area
    return inst, ignore


def _scores(rng: np.random.Generator, n: int, ties: bool) -> np.ndarray:
    if ties:  # few distinct values: ties within and across images
        return rng.choice(np.round(rng.random(4), 3), n)
    return rng.random(n)


def _predictions(rng, inst, kind: str, ties: bool, crowded: int):
    """Per plane: overlapping boxes or masks near the instances and anywhere; plane 0 none,
    plane ``crowded`` more than 100."""
    n_img = inst.shape[0]
    per_plane = []
    for p in range(n_img):
        n = 0 if p == 0 else (130 if p == crowded else int(rng.integers(1, 25)))
        r0, c0 = rng.uniform(0, SIZE - 4, (2, n))
        h, w = rng.uniform(2, 14, (2, n))
        boxes = np.stack([r0, c0, np.minimum(r0 + h, SIZE), np.minimum(c0 + w, SIZE)], axis=1)
        per_plane.append((boxes, _scores(rng, n, ties)))
    if kind == "bbox":
        return Objects.from_boxes(
            [b for b, _ in per_plane], [s for _, s in per_plane], shape=(SIZE, SIZE)
        )
    masks = []
    for boxes, _ in per_plane:
        m = np.zeros((len(boxes), SIZE, SIZE), bool)
        for k, (a, b, c, d) in enumerate(np.round(boxes).astype(int)):
            m[k, a : max(c, a + 1), b : max(d, b + 1)] = True
        masks.append(m)
    return Objects.from_masks(masks, [s for _, s in per_plane])


def _ours(inst, ignore, obj, kind, cuts):
    """AP50, AP50:95 of the predictions, states built batch by batch and merged."""
    total = None
    rule = Matching(kind="box" if kind == "bbox" else "mask")
    for lo, hi in itertools.pairwise(cuts):
        sel = (obj.plane >= lo) & (obj.plane < hi)
        part = _subset(obj, sel, lo, hi - lo)
        gt = ground_truth(inst[lo:hi], ignore[lo:hi])
        state = ObjectState(replicates=0)
        info = [ImageInfo(str(j), order=j) for j in range(lo, hi)]
        state.update(match_batch(part, gt, rule), part, gt, info)
        total = state if total is None else total + state
    ap = total.ap()
    return float(ap[0]), float(np.mean(ap))


def _subset(obj: Objects, sel: np.ndarray, lo: int, planes: int) -> Objects:
    if obj.geometry == "box":
        return Objects.from_boxes(
            obj.box[sel], obj.score[sel], shape=obj.shape, plane=obj.plane[sel] - lo, planes=planes
        )
    h, w = obj.shape
    pixels = [obj.masks.of(k) - obj.plane[k] * h * w for k in np.flatnonzero(sel)]
    return Objects.from_pixel_lists(
        pixels, obj.score[sel], shape=obj.shape, plane=obj.plane[sel] - lo, planes=planes
    )


def _pycocotools(inst, ignore, obj, kind):
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    ex = CocoExport("t")
    batch = {
        "instances": torch.as_tensor(inst)[:, None],
        "ignore": torch.as_tensor(ignore)[:, None],
        "meta": [{"name": str(i), "index": i} for i in range(len(inst))],
    }
    ex.add(batch, {"d": obj})
    ex._category("target")
    results = [{**r, "category_id": 1} for r in ex.results["d"]]
    with contextlib.redirect_stdout(io.StringIO()):
        gt = COCO()
        gt.dataset = {
            "images": ex.images,
            "annotations": ex.annotations,
            "categories": [{"id": i, "name": n} for n, i in ex.categories.items()],
        }
        gt.createIndex()
        dt = gt.loadRes(results)
        ev = COCOeval(gt, dt, kind)
        ev.params.useCats = 0
        ev.params.maxDets = [1, 10, 100_000]
        ev.evaluate()
        ev.accumulate()
    prec = ev.eval["precision"][:, :, 0, 0, -1]

    def ap(p):
        return float(p[p > -1].mean()) if (p > -1).any() else float("nan")

    return ap(prec[0]), float(np.mean([ap(p) for p in prec]))


@settings(max_examples=16, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    kind=st.sampled_from(["bbox", "segm"]),
    ties=st.booleans(),
    cut=st.integers(1, 3),
)
def test_ap_equals_pycocotools_on_continuous_scores(seed, kind, ties, cut):
    rng = np.random.default_rng(seed)
    inst, ignore = _truth(rng, 4)
    if inst.max() == 0:
        inst[1, 5:9, 5:9] = 1
    obj = _predictions(rng, inst, kind, ties, crowded=1 + seed % 3)
    ours = _ours(inst, ignore, obj, kind, [0, cut, 4])
    ref = _pycocotools(inst, ignore, obj, kind)
    assert ours == pytest.approx(ref, abs=1e-6)


def test_more_than_100_detections_per_image_are_all_ranked():
    """No cap: the 101st detection of an image, a true positive, raises AP."""
    inst = np.zeros((1, SIZE, SIZE), np.int32)
    inst[0, 30:40, 30:40] = 1
    boxes = np.tile([[0.0, 0.0, 4.0, 4.0]], (101, 1))
    boxes[100] = (30, 30, 40, 40)
    scores = np.linspace(1.0, 0.5, 101)
    obj = Objects.from_boxes(boxes, scores, shape=(SIZE, SIZE))
    ours = _ours(inst, np.zeros_like(inst, bool), obj, "bbox", [0, 1])
    assert ours[0] == pytest.approx(1 / 101, abs=1e-9)
