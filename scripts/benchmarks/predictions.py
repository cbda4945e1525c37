"""Benchmark cases: scoring a saved results file, from the files on disk to the tables, with
torchsar against pycocotools and faster-coco-eval (AP only).

Synthetic COCO sets, written once into a temporary folder as ``gt.json`` and
``results.json`` only (no image file: neither pycocotools nor torchsar needs one): images of
``SIZE`` x ``SIZE`` px (800 x 800), about 8 ground-truth boxes each (float coordinates,
overlapping ones allowed) in 3 categories, about 10 detections each (jittered boxes of the
targets, some with another category, and random boxes; continuous scores). A second set of
masks (``N_MASK_IMAGES`` images of ``MASK_SIZE`` px, RLE ground truth and detections)
checks the segm route. The AP of each implementation is checked equal before timing (every
detection ranked: the SAR mode).

- ours: ``torchsar_eval.evaluate("coco:gt.json", [predictions("results.json")])`` with
  ``replicates=0`` (AP and the operating point, no interval) and with the default tables
  (200 bootstrap replicates: intervals, breakdowns, FROC, PR);
- references: ``COCO(gt)``, ``loadRes``, ``evaluate``, ``accumulate``, ``summarize``
  (pycocotools, and faster-coco-eval's ``COCOeval_faster`` when installed).

Every run reads the files again (the predictions cache is cleared). State cost: the object
records take :data:`~torchsar.metrics.records.BYTES_PER_DETECTION` bytes per detection,
:data:`~torchsar.metrics.records.BYTES_PER_TARGET` per target and
:data:`~torchsar.metrics.records.BYTES_PER_IMAGE` per image.

Run with ``python scripts/benchmark.py --topic predictions --repeat 3``.
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
import tempfile
import warnings
from collections.abc import Callable
from functools import cache, partial
from pathlib import Path

import numpy as np
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import torchsar_eval as te
from torchsar_eval.saved import detector as saved_detector

SIZES = (200, 2000)
SIZE, N_GT, N_DET, CATEGORIES = 800, 8, 10, 3
N_MASK_IMAGES, MASK_SIZE = 100, 256


@cache
def box_files(n_images: int) -> tuple[Path, Path]:
    """``(gt.json, results.json)`` of the box set of ``n_images`` (written once)."""
    rng = np.random.default_rng(n_images)
    images, anns, dets = [], [], []
    for i in range(1, n_images + 1):
        images.append({"id": i, "file_name": f"{i:05d}.png", "height": SIZE, "width": SIZE})
        targets = []
        for _ in range(int(rng.poisson(N_GT))):
            w, h = rng.uniform(10, 80, 2)
            x, y = rng.uniform(0, SIZE - 100, 2)
            c = int(rng.integers(1, CATEGORIES + 1))
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": i,
                    "category_id": c,
                    "bbox": [x, y, w, h],
                    "area": w * h,
                    "iscrowd": 0,
                }
            )
            targets.append((x, y, w, h, c))
        for _ in range(int(rng.poisson(N_DET))):
            if targets and rng.random() < 0.6:
                x, y, w, h, c = targets[int(rng.integers(len(targets)))]
                x, y = x + rng.normal(0, 3), y + rng.normal(0, 3)
                w, h = w * rng.uniform(0.8, 1.2), h * rng.uniform(0.8, 1.2)
                if rng.random() < 0.1:
                    c = int(rng.integers(1, CATEGORIES + 1))
            else:
                w, h = rng.uniform(10, 80, 2)
                x, y = rng.uniform(0, SIZE - 100, 2)
                c = int(rng.integers(1, CATEGORIES + 1))
            dets.append(
                {
                    "image_id": i,
                    "category_id": c,
                    "bbox": [x, y, w, h],
                    "score": float(rng.random()),
                }
            )
    cats = [{"id": k, "name": f"class{k}"} for k in range(1, CATEGORIES + 1)]
    return _write({"images": images, "annotations": anns, "categories": cats}, dets)


@cache
def mask_files() -> tuple[Path, Path]:
    """``(gt.json, results.json)`` of the mask set (RLE ground truth and detections)."""
    rng = np.random.default_rng(1)
    images, anns, dets = [], [], []
    for i in range(1, N_MASK_IMAGES + 1):
        images.append(
            {"id": i, "file_name": f"{i:05d}.png", "height": MASK_SIZE, "width": MASK_SIZE}
        )
        ships = []
        for _ in range(N_GT):
            h, w = rng.integers(6, 40, 2)
            r, c = rng.integers(0, MASK_SIZE - 40, 2)
            m = np.zeros((MASK_SIZE, MASK_SIZE), bool)
            m[r : r + h, c : c + w] = True
            ships.append((r, c, h, w))
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": i,
                    "category_id": 1,
                    "iscrowd": 0,
                    "segmentation": _rle(m),
                    "area": float(m.sum()),
                    "bbox": [float(c), float(r), float(w), float(h)],
                }
            )
        for _ in range(N_DET):
            r, c, h, w = ships[int(rng.integers(len(ships)))]
            r, c = int(r + rng.normal(0, 2)), int(c + rng.normal(0, 2))
            m = np.zeros((MASK_SIZE, MASK_SIZE), bool)
            m[max(r, 0) : r + h, max(c, 0) : c + w] = True
            dets.append(
                {
                    "image_id": i,
                    "category_id": 1,
                    "segmentation": _rle(m),
                    "score": float(rng.random()),
                }
            )
    return _write(
        {"images": images, "annotations": anns, "categories": [{"id": 1, "name": "ship"}]}, dets
    )


def _write(gt: dict, dets: list) -> tuple[Path, Path]:
    root = Path(tempfile.mkdtemp(prefix="torchsar-bench-"))
    (root / "gt.json").write_text(json.dumps(gt))
    (root / "results.json").write_text(json.dumps(dets))
    return root / "gt.json", root / "results.json"


def _rle(m: np.ndarray) -> dict:
    rle = mask_utils.encode(np.asfortranarray(m.astype(np.uint8)))
    rle["counts"] = rle["counts"].decode()
    return rle


def torchsar_ap(files: tuple[Path, Path], iou_type: str, replicates: int) -> float:
    """AP50:95 by the public route from the files (every file read again)."""
    saved_detector._TABLES.clear()
    gt, results = files
    rule = te.Matching(kind="box" if iou_type == "bbox" else "mask")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # display scaling: no design Pfa (nothing reads it)
        res = te.evaluate(
            {"set": f"coco:{gt}"},
            [te.predictions(results, name="cnn")],
            scoring=te.Scoring(matching=rule, replicates=replicates),
            progress=False,
        )
    return float(res.summary.ap50_95.iloc[0])


def pycocotools_ap(files: tuple[Path, Path], iou_type: str, evaluator=COCOeval, coco=COCO) -> float:
    """AP50:95 by pycocotools (or faster-coco-eval); no image has 100 detections, so its
    cap ranks every one, as torchsar."""
    gt, results = files
    with contextlib.redirect_stdout(io.StringIO()):
        g = coco(str(gt))
        ev = evaluator(g, g.loadRes(str(results)), iou_type)
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    return float(ev.stats[0])


def _faster() -> tuple | None:
    try:
        from faster_coco_eval import COCO as FCOCO
        from faster_coco_eval import COCOeval_faster
    except ImportError:
        return None
    return FCOCO, COCOeval_faster


def cases() -> list[tuple[str, Callable, Callable]]:
    sets = [(f"{n} images {SIZE}x{SIZE}, bbox", box_files(n), "bbox") for n in SIZES]
    sets.append((f"{N_MASK_IMAGES} images {MASK_SIZE}x{MASK_SIZE}, segm", mask_files(), "segm"))
    fast = _faster()
    out = []
    for label, files, iou_type in sets:
        ref = partial(pycocotools_ap, files, iou_type)
        ap_only = partial(torchsar_ap, files, iou_type, 0)
        assert abs(ap_only() - ref()) < 1e-9, (label, ap_only(), ref())
        out.append((f"predictions {label}: AP only (replicates 0) vs pycocotools", ap_only, ref))
        out.append(
            (
                f"predictions {label}: default tables vs pycocotools",
                partial(torchsar_ap, files, iou_type, 200),
                ref,
            )
        )
        if fast is not None:
            fref = partial(pycocotools_ap, files, iou_type, fast[1], fast[0])
            assert abs(fref() - ref()) < 1e-9
            out.append((f"predictions {label}: AP only vs faster-coco-eval", ap_only, fref))
            out.append(
                (
                    f"predictions {label}: default tables vs faster-coco-eval",
                    partial(torchsar_ap, files, iou_type, 200),
                    fref,
                )
            )
    return out
