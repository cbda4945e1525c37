"""Benchmark cases for the COCO-compatible state against pycocotools and faster-coco-eval.

One synthetic bbox set: 500 images x 20 instances (3 categories, a few crowd) x 100
detections (jittered instances and random boxes, scores with ties). The 12 stats of every
implementation are checked equal to pycocotools' before timing.

- ``coco_compat update+stats``: :class:`CocoState` from the per-image inputs (IoUs given);
- ``... incl. IoU``: the same plus the IoU matrices by ``pycocotools.mask.iou`` per image;
- references: ``COCOeval`` evaluate + accumulate + summarize (its evaluate computes the IoUs),
  and the same with the IoUs precomputed; faster-coco-eval's ``COCOeval_faster`` when
  installed.

Run with ``python scripts/benchmark.py --topic coco_compat --repeat 1``.
"""

from __future__ import annotations

import contextlib
import copy
import io
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from torchsar.metrics.coco_compat import CocoImage, CocoState

N_IMAGES, N_GT, N_DET, SIZE, CATS = 500, 20, 100, 512, (1, 2, 3)


def dataset(seed: int = 0) -> tuple[dict, list]:
    """COCO ground truth (dict) and results (list) of the synthetic set."""
    rng = np.random.default_rng(seed)
    images, anns, dets = [], [], []
    for i in range(1, N_IMAGES + 1):
        images.append({"id": i, "height": SIZE, "width": SIZE})
        side = np.exp(rng.uniform(np.log(8), np.log(160), (N_GT, 2)))
        xy = rng.uniform(0, SIZE - side)
        boxes = np.round(np.concatenate([xy, side], 1), 1)
        cats = rng.choice(CATS, N_GT)
        for b, c in zip(boxes, cats, strict=True):
            crowd = int(rng.random() < 0.03)
            ann = {"id": len(anns) + 1, "image_id": i, "category_id": int(c), "iscrowd": crowd}
            anns.append(ann | {"bbox": b.tolist(), "area": float(b[2] * b[3])})
        for _ in range(N_DET):
            if rng.random() < 0.7:
                k = int(rng.integers(N_GT))
                b = boxes[k] + rng.normal(0, 0.1, 4) * boxes[k, [2, 3, 2, 3]]
                c = int(cats[k]) if rng.random() < 0.9 else int(rng.choice(CATS))
            else:
                s = np.exp(rng.uniform(np.log(8), np.log(160), 2))
                b, c = np.concatenate([rng.uniform(0, SIZE - s), s]), int(rng.choice(CATS))
            b[2:] = np.maximum(b[2:], 1)
            score = float(np.round(rng.random(), 3))
            dets.append({"image_id": i, "category_id": c, "bbox": b.tolist(), "score": score})
    gt = {"images": images, "annotations": anns, "categories": [{"id": c} for c in CATS]}
    return gt, dets


def coco_images(gt: dict, dets: list) -> list[CocoImage]:
    """Per-image inputs; IoUs by pycocotools.mask.iou (as COCOeval's)."""
    by_img: dict[int, tuple[list, list]] = {im["id"]: ([], []) for im in gt["images"]}
    for a in gt["annotations"]:
        by_img[a["image_id"]][0].append(a)
    for d in dets:
        by_img[d["image_id"]][1].append(d)
    out = []
    for order, i in enumerate(sorted(by_img)):
        g, d = by_img[i]
        gb = np.array([a["bbox"] for a in g], np.float64).reshape(-1, 4)
        db = np.array([x["bbox"] for x in d], np.float64).reshape(-1, 4)
        crowd = np.array([a["iscrowd"] for a in g], np.uint8)
        iou = mask_utils.iou(db, gb, crowd) if len(g) and len(d) else np.zeros((len(d), len(g)))
        out.append(
            CocoImage(
                order,
                [a["category_id"] for a in g],
                [a["area"] for a in g],
                crowd.astype(bool),
                [x["category_id"] for x in d],
                [x["score"] for x in d],
                db[:, 2] * db[:, 3],
                np.asarray(iou, np.float64),
            )
        )
    return out


def ours(images: list[CocoImage]) -> np.ndarray:
    state = CocoState()
    state.update(images)
    return state.stats()


def evaluator(gt: dict, dets: list, cls=COCOeval, coco_cls=COCO, ious: dict | None = None):
    """A ``cls`` evaluator of the set, ready to run (IoUs looked up in ``ious`` if given)."""
    with contextlib.redirect_stdout(io.StringIO()):
        coco = coco_cls()
        coco.dataset = copy.deepcopy(gt)
        coco.createIndex()
        ev = cls(coco, coco.loadRes(copy.deepcopy(dets)), "bbox")
    if ious is not None:
        ev.computeIoU = lambda img, cat: ious[img, cat]
    return ev


def reference(ev) -> np.ndarray:
    """evaluate + accumulate + summarize: the 12 stats."""
    with contextlib.redirect_stdout(io.StringIO()):
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    return np.array(ev.stats)


def cases() -> list[tuple[str, Callable, Callable]]:
    gt, dets = dataset()
    images = coco_images(gt, dets)
    ev = evaluator(gt, dets)
    want = reference(ev)
    assert np.array_equal(ours(images), want), (ours(images), want)
    given = evaluator(gt, dets, ious=ev.ious)
    name = f"coco_compat {N_IMAGES} img x {N_GT} gt x {N_DET} det bbox"
    out = [
        (f"{name}: update+stats vs pycocotools", lambda: ours(images), partial(reference, ev)),
        (
            f"{name}: update+stats vs pycocotools, IoUs given",
            lambda: ours(images),
            partial(reference, given),
        ),
        (
            f"{name}: incl. IoU vs pycocotools",
            lambda: ours(coco_images(gt, dets)),
            partial(reference, ev),
        ),
    ]
    try:
        import faster_coco_eval
    except ImportError:
        return out
    fast = evaluator(gt, dets, faster_coco_eval.COCOeval_faster, faster_coco_eval.COCO)
    assert np.array_equal(reference(fast), want), (reference(fast), want)
    out.append(
        (
            f"{name}: update+stats vs faster-coco-eval",
            lambda: ours(images),
            partial(reference, fast),
        )
    )
    out.append(
        (
            f"{name}: incl. IoU vs faster-coco-eval",
            lambda: ours(coco_images(gt, dets)),
            partial(reference, fast),
        )
    )
    return out
