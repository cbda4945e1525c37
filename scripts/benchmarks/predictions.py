"""Benchmark cases: scoring a saved predictions file, from the files on disk to AP, with
torchsar (exact AP, every table: FROC, bootstrap intervals, breakdowns) against
pycocotools and faster-coco-eval (AP only).

A synthetic COCO set is written once into a temporary folder: ``N_IMAGES`` PNG images of
``SIZE`` px with ``N_GT`` ships each (RLE masks) and a results file of ``N_DET`` detections
per image (jittered ships and random boxes, continuous scores), as boxes and as masks. The
AP of each implementation is checked equal before timing.

- ours: ``torchsar_eval.evaluate("coco:gt.json", [predictions(results.json)])`` with the
  default scoring (the SAR defaults: prescreening rule at the operating point, 100
  bootstrap replicates) and with ``--coco-compatible`` on top;
- references: ``COCO(gt)``, ``loadRes``, ``evaluate``, ``accumulate``, ``summarize``
  (pycocotools, and faster-coco-eval's ``COCOeval_faster`` when installed).

Run with ``python scripts/benchmark.py --topic predictions --repeat 3``.
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
import tempfile
from collections.abc import Callable
from functools import cache, partial
from pathlib import Path

import numpy as np
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval
from skimage import io as skio

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import torchsar_eval as te

N_IMAGES, N_GT, N_DET, SIZE = 300, 8, 100, 256


@cache
def files() -> tuple[Path, Path, Path]:
    """``(gt.json, boxes.json, masks.json)`` of the synthetic set (written once)."""
    rng = np.random.default_rng(0)
    root = Path(tempfile.mkdtemp(prefix="torchsar-bench-"))
    images, anns, boxes, masks = [], [], [], []
    for i in range(1, N_IMAGES + 1):
        name = f"{i:05d}.png"
        skio.imsave(root / name, rng.integers(0, 255, (SIZE, SIZE)).astype(np.uint8),
                    check_contrast=False)  # fmt: skip
        images.append({"id": i, "file_name": name, "height": SIZE, "width": SIZE})
        taken = np.zeros((SIZE, SIZE), bool)
        ships = []
        for _ in range(N_GT):
            h, w = rng.integers(6, 40, 2)
            r, c = rng.integers(0, SIZE - 40, 2)
            m = np.zeros((SIZE, SIZE), bool)
            m[r : r + h, c : c + w] = True
            if (m & taken).any():
                continue
            taken |= m
            ships.append((r, c, h, w))
            anns.append({"id": len(anns) + 1, "image_id": i, "category_id": 1, "iscrowd": 0,
                         "segmentation": _rle(m), "area": float(m.sum()),
                         "bbox": [float(c), float(r), float(w), float(h)]})  # fmt: skip
        for _ in range(N_DET):
            if ships and rng.random() < 0.5:
                r, c, h, w = ships[int(rng.integers(len(ships)))]
                r, c = r + rng.normal(0, 2), c + rng.normal(0, 2)
                h, w = h * rng.uniform(0.7, 1.3), w * rng.uniform(0.7, 1.3)
            else:
                h, w = rng.uniform(4, 40, 2)
                r, c = rng.uniform(0, SIZE - 40, 2)
            score = float(rng.random())
            box = {"image_id": i, "category_id": 1, "bbox": [c, r, w, h], "score": score}
            boxes.append(box)
            m = np.zeros((SIZE, SIZE), bool)
            m[int(r) : int(r + h) + 1, int(c) : int(c + w) + 1] = True
            masks.append({**box, "segmentation": _rle(m)})
    gt = {"images": images, "annotations": anns, "categories": [{"id": 1, "name": "ship"}]}
    paths = root / "gt.json", root / "boxes.json", root / "masks.json"
    for path, data in zip(paths, (gt, boxes, masks), strict=True):
        path.write_text(json.dumps(data))
    return paths


def _rle(m: np.ndarray) -> dict:
    rle = mask_utils.encode(np.asfortranarray(m.astype(np.uint8)))
    rle["counts"] = rle["counts"].decode()
    return rle


def torchsar_ap(results: Path, iou_type: str, coco: bool = False) -> float:
    gt = files()[0]
    rule = te.Matching(kind="box" if iou_type == "bbox" else "mask")
    res = te.evaluate(f"coco:{gt}?type=display", [te.predictions(results, threshold=0.5)],
                      scoring=te.Scoring(matching=rule, coco_compatible=coco),
                      progress=False)  # fmt: skip
    return float(res.summary.ap50_95.iloc[0])


def pycocotools_ap(results: Path, iou_type: str, evaluator=COCOeval, coco=COCO) -> float:
    with contextlib.redirect_stdout(io.StringIO()):
        gt = coco(str(files()[0]))
        ev = evaluator(gt, gt.loadRes(str(results)), iou_type)
        ev.params.maxDets = [1, 10, N_DET]  # every detection ranked, as torchsar
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
    _, boxes, masks = files()
    out = []
    for iou_type, results in (("bbox", boxes), ("segm", masks)):
        ours = partial(torchsar_ap, results, iou_type)
        ref = partial(pycocotools_ap, results, iou_type)
        assert abs(ours() - ref()) < 1e-9, (iou_type, ours(), ref())
        size = f"{N_IMAGES} images x {N_DET} detections, {iou_type}"
        out.append((f"predictions {size}: torchsar evaluate vs pycocotools", ours, ref))
        out.append((f"predictions {size}: torchsar evaluate + coco-compatible vs pycocotools",
                    partial(torchsar_ap, results, iou_type, True), ref))  # fmt: skip
        fast = _faster()
        if fast is not None:
            fref = partial(pycocotools_ap, results, iou_type, fast[1], fast[0])
            assert abs(fref() - ref()) < 1e-9
            out.append((f"predictions {size}: torchsar evaluate vs faster-coco-eval", ours, fref))
    return out
