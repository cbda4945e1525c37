"""CocoState against pycocotools' COCOeval (evaluate + accumulate + summarize) on random
datasets, bbox and segm, and its invariance to how the images are split and merged."""

from __future__ import annotations

import contextlib
import copy
import io
import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

from torchsar.errors import InputValueError, OptionError
from torchsar.metrics.coco_compat import (
    COCO_AREAS,
    COCO_MAX_DETS,
    CocoImage,
    CocoState,
)
from torchsar.metrics.matching import COCO_IOUS


def _box(rng, h, w, near=None):
    """An integer xywh box inside an h x w image: random sizes over the COCO area ranges
    (sides of exactly 32 and 96 now and then), or a jitter of ``near``."""
    if near is not None:
        x, y, bw, bh = near
        x, y = x + rng.integers(-4, 5), y + rng.integers(-4, 5)
        bw, bh = max(1, bw + rng.integers(-4, 5)), max(1, bh + rng.integers(-4, 5))
    else:
        side = rng.choice([32, 96]) if rng.random() < 0.1 else int(np.exp(rng.uniform(0.7, 5)))
        bw, bh = side, max(1, int(side * rng.uniform(0.5, 1.5)))
        x, y = rng.integers(0, w), rng.integers(0, h)
    x, y = int(np.clip(x, 0, w - 1)), int(np.clip(y, 0, h - 1))
    return [x, y, int(min(bw, w - x)), int(min(bh, h - y))]


def _rle(rng, box, h, w):
    """The box's mask with a few holes now and then, as compressed RLE."""
    m = np.zeros((h, w), np.uint8)
    x, y, bw, bh = box
    m[y : y + bh, x : x + bw] = 1 if rng.random() < 0.5 else rng.random((bh, bw)) < 0.85
    if not m.any():
        m[y, x] = 1
    return mask_utils.encode(np.asfortranarray(m))


def _dataset(seed: int, iou_type: str):
    """Random COCO ground truth and results, as JSON-like dicts: 1-6 images, 0-12 instances
    over 2-3 categories (some crowd, some duplicated), 0-30 or 120-160 detections (jittered
    instances, random boxes, rounded scores for ties, exact duplicates; the many detections of
    an image mostly in one category, over the 100 cap)."""
    rng = np.random.default_rng(seed)
    cats = rng.choice([1, 2, 5, 7, 11], rng.integers(2, 4), replace=False).tolist()
    n_img = int(rng.integers(1, 7))
    ids = (rng.choice(1000, n_img, replace=False) + 1).tolist()
    images, gts, dts = [], {}, {}
    for i in ids:
        h, w = (int(v) for v in rng.integers(40, 201, 2))
        images.append({"id": i, "height": h, "width": w})
        gts[i], dts[i] = [], []
        for _ in range(0 if rng.random() < 0.15 else int(rng.integers(0, 13))):
            if gts[i] and rng.random() < 0.1:
                gts[i].append(dict(gts[i][int(rng.integers(len(gts[i])))]))
                continue
            box, crowd = _box(rng, h, w), bool(rng.random() < 0.12)
            ann = {"image_id": i, "category_id": rng.choice(cats).item(), "bbox": box}
            ann["iscrowd"] = int(crowd)
            if iou_type == "segm":
                ann["segmentation"] = _rle(rng, box, h, w)
                ann["area"] = float(mask_utils.area(ann["segmentation"]))
            else:
                ann["area"] = float(box[2] * box[3])
            if rng.random() < 0.05:
                ann["area"] = float(rng.choice([32.0**2, 96.0**2]))
            gts[i].append(ann)
        n_det = rng.choice(
            [0, int(rng.integers(1, 31)), int(rng.integers(120, 161))], p=[0.15, 0.65, 0.2]
        )
        for _ in range(n_det):
            if dts[i] and rng.random() < 0.08:
                dts[i].append(dict(dts[i][int(rng.integers(len(dts[i])))]))
                continue
            g = gts[i][int(rng.integers(len(gts[i])))] if gts[i] and rng.random() < 0.6 else None
            box = _box(rng, h, w, None if g is None else g["bbox"])
            cat = (
                g["category_id"]
                if g is not None and rng.random() < 0.8
                else rng.choice(cats).item()
            )
            if n_det >= 120 and rng.random() < 0.9:  # over the cap in one category
                cat = cats[0]
            score = float(rng.random())
            if rng.random() < 0.3:
                score = round(score, 1)
            det = {"image_id": i, "category_id": cat, "score": score}
            if iou_type == "segm":
                det["segmentation"] = _rle(rng, box, h, w)
            else:
                det["bbox"] = [float(v) for v in box]
            dts[i].append(det)
    if not any(dts.values()):  # pycocotools' loadRes needs one detection
        i = ids[0]
        det = {"image_id": i, "category_id": cats[0], "score": 0.5}
        det |= (
            {"segmentation": _rle(rng, [0, 0, 5, 5], 40, 40)}
            if iou_type == "segm"
            else {"bbox": [0.0, 0.0, 5.0, 5.0]}
        )
        dts[i].append(det)
    return images, gts, dts


def _file_order(rng, per_image: dict) -> list:
    """All annotations, images interleaved at random, each image's own order kept."""
    labels = rng.permutation([i for i, anns in per_image.items() for _ in anns])
    pos = dict.fromkeys(per_image, 0)
    out = []
    for i in labels.tolist():
        out.append(per_image[i][pos[i]])
        pos[i] += 1
    return out


def _pycocotools(images, gts, dts, iou_type, seed=0, **params):
    """COCOeval on the dicts, with ``params`` set on ``COCOeval.params``: (stats, precision,
    recall)."""
    rng = np.random.default_rng(seed)
    anns = [dict(a, id=k + 1) for k, a in enumerate(_file_order(rng, gts))]
    seen = {a["category_id"] for a in anns} | {d["category_id"] for v in dts.values() for d in v}
    with contextlib.redirect_stdout(io.StringIO()):
        gt = COCO()
        gt.dataset = {
            "images": images,
            "annotations": anns,
            "categories": [{"id": c} for c in sorted(seen)],
        }
        gt.createIndex()
        dt = gt.loadRes(copy.deepcopy(_file_order(rng, dts)))
        ev = COCOeval(gt, dt, iou_type)
        ev.params.useCats = 1
        for k, v in params.items():
            setattr(ev.params, k, v)
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    return np.array(ev.stats), ev.eval["precision"], ev.eval["recall"]


def _segms(anns: list) -> list:
    return [a["segmentation"] for a in anns]


def _boxes(anns: list) -> np.ndarray:
    return np.array([a["bbox"] for a in anns], np.float64)


def _coco_images(images, gts, dts, iou_type) -> list[CocoImage]:
    """The CocoImage of every image; IoUs from pycocotools.mask.iou, as COCOeval's."""
    rank = {i: r for r, i in enumerate(sorted(im["id"] for im in images))}
    out = []
    for im in images:
        g, d = gts[im["id"]], dts[im["id"]]
        crowd = [a["iscrowd"] for a in g]
        if g and d:
            objs = _segms if iou_type == "segm" else _boxes
            iou = np.asarray(mask_utils.iou(objs(d), objs(g), crowd), np.float64)
        else:
            iou = np.zeros((len(d), len(g)))
        if iou_type == "segm":
            det_area = [float(mask_utils.area(x["segmentation"])) for x in d]
        else:
            det_area = [x["bbox"][2] * x["bbox"][3] for x in d]
        out.append(
            CocoImage(
                order=rank[im["id"]],
                gt_category=[a["category_id"] for a in g],
                gt_area=[a["area"] for a in g],
                gt_crowd=[bool(c) for c in crowd],
                det_category=[x["category_id"] for x in d],
                det_score=[x["score"] for x in d],
                det_area=det_area,
                iou=iou,
            )
        )
    return out


def _assert_same(state: CocoState, ref) -> None:
    stats, precision, recall = ref
    np.testing.assert_allclose(state.stats(), stats, rtol=0, atol=1e-12)
    assert np.array_equal(state.stats(), stats)
    assert np.array_equal(state.precision(), precision)
    assert np.array_equal(state.recall(), recall)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), iou_type=st.sampled_from(["bbox", "segm"]))
def test_matches_pycocotools_and_any_split(seed, iou_type):
    images, gts, dts = _dataset(seed, iou_type)
    coco = _coco_images(images, gts, dts, iou_type)
    rng = np.random.default_rng(seed)
    whole = CocoState()
    whole.update([coco[i] for i in rng.permutation(len(coco))])
    _assert_same(whole, _pycocotools(images, gts, dts, iou_type, seed))
    # split at a random point, updated in pieces, merged either way round
    cut = int(rng.integers(0, len(coco) + 1))
    a, b = CocoState(), CocoState()
    a.update(coco[:cut])
    for im in coco[cut:]:
        b.update([im])
    a = pickle.loads(pickle.dumps(a))  # as from a worker
    for merged in (a + b, b + a):
        assert merged == whole
        assert np.array_equal(merged.stats(), whole.stats())
        assert merged.categories == whole.categories


def _tiny(boxes_gt, boxes_dt, crowd=None, cats_gt=None, cats_dt=None, scores=None):
    """One 100 x 100 image, bbox: (images, gts, dts) dicts."""
    n, m = len(boxes_gt), len(boxes_dt)
    crowd, cats_gt = crowd or [0] * n, cats_gt or [1] * n
    cats_dt, scores = cats_dt or [1] * m, scores or [0.9 - 0.1 * k for k in range(m)]
    gts = [
        {"image_id": 1, "category_id": c, "bbox": b, "area": float(b[2] * b[3]), "iscrowd": k}
        for b, c, k in zip(boxes_gt, cats_gt, crowd, strict=True)
    ]
    dts = [
        {"image_id": 1, "category_id": c, "bbox": [float(v) for v in b], "score": s}
        for b, c, s in zip(boxes_dt, cats_dt, scores, strict=True)
    ]
    return [{"id": 1, "height": 100, "width": 100}], {1: gts}, {1: dts}


@pytest.mark.parametrize(
    "case",
    [
        # only crowd ground truth: every entry -1
        dict(
            boxes_gt=[[0, 0, 40, 40], [50, 50, 20, 20]],
            boxes_dt=[[0, 0, 30, 30], [60, 60, 5, 5], [10, 80, 9, 9]],
            crowd=[1, 1],
        ),
        # category 2 has detections and no ground truth
        dict(
            boxes_gt=[[0, 0, 40, 40]],
            boxes_dt=[[0, 0, 38, 40], [0, 0, 40, 40], [60, 60, 9, 9]],
            cats_dt=[1, 2, 2],
        ),
        # a tie of IoU 0.5 with two instances goes to the later one, leaving the earlier one
        # to the second detection
        dict(boxes_gt=[[0, 0, 10, 10], [10, 0, 10, 10]], boxes_dt=[[0, 0, 20, 10], [0, 0, 10, 10]]),
        # the same with the instances in the other order: the second detection finds none
        dict(boxes_gt=[[10, 0, 10, 10], [0, 0, 10, 10]], boxes_dt=[[0, 0, 20, 10], [0, 0, 10, 10]]),
        # tied IoUs with two identical instances, tied scores
        dict(
            boxes_gt=[[0, 0, 10, 10], [0, 0, 10, 10]],
            boxes_dt=[[0, 0, 10, 8]] * 3,
            scores=[0.5] * 3,
        ),
    ],
)
def test_edge_cases_match_pycocotools(case):
    images, gts, dts = _tiny(**case)
    state = CocoState()
    state.update(_coco_images(images, gts, dts, "bbox"))
    _assert_same(state, _pycocotools(images, gts, dts, "bbox"))


def test_other_parameters_match_pycocotools():
    """Other thresholds (1.0: pycocotools clamps it to 1 - 1e-10), caps (stat 0 reads cap 100
    whatever the caps) and area ranges (stats of a missing label are -1)."""
    images, gts, dts = _dataset(433, "bbox")
    gts[images[0]["id"]].append(dict(gts[images[0]["id"]][0], iscrowd=0, area=50.0))
    x, y, w, h = gts[images[0]["id"]][-1]["bbox"]
    near = {"image_id": images[0]["id"], "category_id": gts[images[0]["id"]][-1]["category_id"]}
    dts[images[0]["id"]].append(dict(near, bbox=[x, y, w, h * (1 - 1e-11)], score=0.3))
    params = dict(
        iou_thresholds=[0.5, 0.75, 1.0],
        max_dets=(20, 1, 5),
        areas={"all": (0.0, 1e10), "small": (0.0, 40.0**2), "tiny": (0.0, 100.0)},
    )
    ref = _pycocotools(
        images,
        gts,
        dts,
        "bbox",
        iouThrs=np.array(params["iou_thresholds"]),
        maxDets=[1, 5, 20],
        areaRng=[list(v) for v in params["areas"].values()],
        areaRngLbl=list(params["areas"]),
    )
    state = CocoState(**params)
    state.update(_coco_images(images, gts, dts, "bbox"))
    _assert_same(state, ref)
    assert state.stats()[0] == -1 and state.stats()[5] == -1 and state.stats()[3] > -1


def test_only_crowd_ground_truth_is_undefined():
    images, gts, dts = _tiny([[0, 0, 40, 40]], [[0, 0, 30, 30]], crowd=[1])
    state = CocoState()
    state.update(_coco_images(images, gts, dts, "bbox"))
    assert (state.stats() == -1).all() and state.categories == [1]


def test_pycocotools_thresholds_not_rounded():
    """pycocotools' 0.9 threshold is 0.8999999999999999: a box pair with exactly that IoU
    matches there (and with COCO_IOUS), but not at a rounded 0.9."""
    rounded_ious = np.round(COCO_IOUS, 2)
    assert np.allclose(rounded_ious, COCO_IOUS) and not np.array_equal(rounded_ious, COCO_IOUS)
    gt = np.array([[0.0, 0.0, 1.0, 1.0]])
    h = next(
        h
        for h in np.nextafter(0.9, 0) - np.arange(20) * 2e-17
        if mask_utils.iou(np.array([[0, 0, 1, h]]), gt, [0])[0, 0] == COCO_IOUS[8]
    )
    images, gts, dts = _tiny([[0, 0, 1, 1]], [[0, 0, 1, h]])
    gts[1][0]["area"] = 2000.0
    coco = _coco_images(images, gts, dts, "bbox")
    exact, rounded = CocoState(), CocoState(iou_thresholds=rounded_ious)
    exact.update(coco)
    rounded.update(coco)
    _assert_same(exact, _pycocotools(images, gts, dts, "bbox"))
    assert exact.stats()[0] == pytest.approx(0.9) and rounded.stats()[0] == pytest.approx(0.8)


def test_empty_state():
    s = CocoState()
    assert (s.stats() == -1).all() and s.categories == []
    assert s.precision().shape == (10, 101, 0, 4, 3) and s.recall().shape == (10, 0, 4, 3)
    assert s + CocoState() == s and sum([s, CocoState()]) == s
    s.update([])
    assert s == CocoState()


def test_images_without_anything_count_as_seen():
    a, b = CocoState(), CocoState()
    a.update([CocoImage(0, [], [], [], [], [], [], np.zeros((0, 0)))])
    assert a != b and (a.stats() == -1).all()


def test_bytes_per_detection():
    assert CocoState().bytes_per_detection == 32
    assert (
        CocoState(areas={"all": COCO_AREAS["all"]}, max_dets=COCO_MAX_DETS).bytes_per_detection
        == 25
    )


def test_refuses_overlapping_images_and_mixed_parameters():
    im = CocoImage(3, [1], [10.0], [False], [1], [0.5], [10.0], [[0.7]])
    a, b = CocoState(), CocoState()
    a.update([im])
    b.update([im])
    with pytest.raises(InputValueError):
        a + b
    with pytest.raises(InputValueError):
        a.update([im, im])
    with pytest.raises(OptionError):
        a + CocoState(max_dets=(1, 10, 50))
