"""Random COCO sets for checking against ``pycocotools``: images of a few sizes, several
categories, float boxes that overlap, polygon and RLE masks that overlap, crowd regions,
images without detections, ties in score, and images with more than 100 detections; with
``pycocotools`` run on them (in memory, quietly) and the same data as torchsar's
:class:`~torchsar.metrics.GroundTruth` and :class:`~torchsar.objects.Objects`."""

from __future__ import annotations

import contextlib
import copy
import io

import numpy as np
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

from torchsar.metrics.truth import GroundTruth, Regions
from torchsar.objects import Objects

CATEGORIES = [{"id": 3, "name": "ship"}, {"id": 7, "name": "tank"}, {"id": 9, "name": "car"}]


def _polygon(rng, x, y, w, h) -> list[float]:
    """A random quadrilateral inside the box ``(x, y, w, h)``."""
    pts = [
        (x + rng.uniform(0, w / 3), y + rng.uniform(0, h / 3)),
        (x + w - rng.uniform(0, w / 3), y + rng.uniform(0, h / 3)),
        (x + w - rng.uniform(0, w / 3), y + h - rng.uniform(0, h / 3)),
        (x + rng.uniform(0, w / 3), y + h - rng.uniform(0, h / 3)),
    ]
    return [float(v) for p in pts for v in p]


def make_set(
    seed: int,
    *,
    n_images: int = 4,
    segm: bool = False,
    crowd: bool = True,
    many: bool = False,
    ties: bool = False,
    categories: int = 3,
):
    """``(gt dict, results list)`` of a random set (see the module docstring)."""
    rng = np.random.default_rng(seed)
    cats = CATEGORIES[:categories]
    images, anns, dets = [], [], []
    for i in range(n_images):
        h, w = int(rng.choice([40, 56])), int(rng.choice([48, 64]))
        iid = int(rng.integers(1, 10_000)) * 10 + i  # ids not in file order
        images.append({"id": iid, "file_name": f"{iid}.png", "height": h, "width": w})
        boxes = []
        for _ in range(int(rng.integers(0, 7))):
            bw, bh = rng.uniform(2, w / 2), rng.uniform(2, h / 2)
            x, y = rng.uniform(0, w - bw), rng.uniform(0, h - bh)
            c = int(rng.choice([c["id"] for c in cats]))
            is_crowd = crowd and rng.random() < 0.15
            ann = {
                "id": len(anns) + 1,
                "image_id": iid,
                "category_id": c,
                "bbox": [float(x), float(y), float(bw), float(bh)],
                "iscrowd": int(is_crowd),
            }
            if segm or is_crowd:
                poly = [_polygon(rng, x, y, bw, bh)]
                if is_crowd or rng.random() < 0.3:  # RLE
                    ann["segmentation"] = mask_utils.frPyObjects(poly, h, w)[0]
                    ann["segmentation"]["counts"] = ann["segmentation"]["counts"].decode()
                else:
                    ann["segmentation"] = poly
            ann["area"] = (
                float(bw * bh)
                if "segmentation" not in ann
                else float(mask_utils.area(_rle(ann["segmentation"], h, w)))
            )
            if is_crowd and not segm:
                ann.pop("segmentation")  # a crowd box in the box set
            anns.append(ann)
            if not is_crowd:
                boxes.append((x, y, bw, bh, c))
        if rng.random() < 0.2:
            continue  # an image without detections
        n_det = int(rng.integers(101, 140)) if many and i == 0 else int(rng.integers(0, 12))
        for _ in range(n_det):
            if boxes and rng.random() < 0.6:
                x, y, bw, bh, c = boxes[int(rng.integers(len(boxes)))]
                x, y = x + rng.normal(0, 1.5), y + rng.normal(0, 1.5)
                bw, bh = bw * rng.uniform(0.7, 1.3), bh * rng.uniform(0.7, 1.3)
                if rng.random() < 0.2:
                    c = int(rng.choice([c["id"] for c in cats]))
            else:
                bw, bh = rng.uniform(2, w / 2), rng.uniform(2, h / 2)
                x, y = rng.uniform(0, w - bw), rng.uniform(0, h - bh)
                c = int(rng.choice([c["id"] for c in cats]))
            x, y = float(np.clip(x, 0.0, w - 1.0)), float(np.clip(y, 0.0, h - 1.0))
            bw, bh = max(min(bw, w - x), 0.5), max(min(bh, h - y), 0.5)
            score = float(rng.integers(0, 5) / 4) if ties else float(rng.random())
            d = {"image_id": iid, "category_id": c, "bbox": [x, y, bw, bh], "score": score}
            if segm:
                rle = mask_utils.frPyObjects([_polygon(rng, x, y, bw, bh)], h, w)[0]
                rle["counts"] = rle["counts"].decode()
                d["segmentation"] = rle
            dets.append(d)
    return {"images": images, "annotations": anns, "categories": cats}, dets


def _rle(seg, h: int, w: int) -> dict:
    if isinstance(seg, list):
        return mask_utils.merge(mask_utils.frPyObjects(seg, h, w))
    if isinstance(seg.get("counts"), list):
        return mask_utils.frPyObjects(seg, h, w)
    return {
        "size": seg["size"],
        "counts": seg["counts"].encode() if isinstance(seg["counts"], str) else seg["counts"],
    }


def pycocotools_eval(
    gt: dict, dets: list, iou_type: str, *, max_dets=(1, 10, 100), use_cats: bool = True
) -> COCOeval:
    """``COCOeval`` run on in-memory data (evaluate, accumulate, summarize), quietly."""
    with contextlib.redirect_stdout(io.StringIO()):
        coco = COCO()
        coco.dataset = copy.deepcopy(gt)
        coco.createIndex()
        res = coco.loadRes(copy.deepcopy(dets)) if dets else COCO()
        if not dets:
            res.dataset = {
                "images": gt["images"],
                "annotations": [],
                "categories": gt["categories"],
            }
            res.createIndex()
        ev = COCOeval(coco, res, iou_type)
        ev.params.maxDets = list(max_dets)
        ev.params.useCats = int(use_cats)
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    return ev


def _pixels(seg, h: int, w: int) -> np.ndarray:
    """Flat row-major pixel indices of a segmentation."""
    m = mask_utils.decode(_rle(seg, h, w)).astype(bool)
    return np.flatnonzero(m.reshape(-1))


def torchsar_inputs(gt: dict, dets: list, iou_type: str):
    """``[(GroundTruth, Objects, image orders)]``, one per image size, of a set: targets as
    given (boxes, or masks for ``segm``), crowd annotations as don't-care regions of their
    class (a mask where given, else a box)."""
    names = {c["id"]: c["name"] for c in gt["categories"]}
    by_size: dict = {}
    ids = sorted(im["id"] for im in gt["images"])
    for im in gt["images"]:
        by_size.setdefault((im["height"], im["width"]), []).append(im)
    out = []
    for (h, w), ims in sorted(by_size.items()):
        ims = sorted(ims, key=lambda im: im["id"])
        plane = {im["id"]: p for p, im in enumerate(ims)}
        t, r = [a for a in gt["annotations"] if a["image_id"] in plane], []
        r = [a for a in t if a["iscrowd"]]
        t = [a for a in t if not a["iscrowd"]]
        truth = GroundTruth.build(
            np.array([plane[a["image_id"]] for a in t], np.int64),
            np.array([_rc(a["bbox"]) for a in t]).reshape(-1, 4),
            planes=len(ims),
            shape=(h, w),
            classes=[names[a["category_id"]] for a in t],
            pixels=[_pixels(a["segmentation"], h, w) if iou_type == "segm" else None for a in t],
            declared_area=np.array([a["area"] for a in t], np.float64),
            crowd=Regions.build(
                np.array([plane[a["image_id"]] for a in r], np.int64),
                np.array([_rc(a["bbox"]) for a in r]).reshape(-1, 4),
                shape=(h, w),
                classes=[names[a["category_id"]] for a in r],
                pixels=[
                    _pixels(a["segmentation"], h, w) if "segmentation" in a else None for a in r
                ],
            ),
        )
        mine = [d for d in dets if d["image_id"] in plane]
        pl = np.array([plane[d["image_id"]] for d in mine], np.int64)
        score = np.array([d["score"] for d in mine], np.float64)
        cls = [names[d["category_id"]] for d in mine]
        if iou_type == "segm":
            obj = Objects.from_pixel_lists(
                [_pixels(d["segmentation"], h, w) for d in mine],
                score,
                shape=(h, w),
                plane=pl,
                planes=len(ims),
                classes=cls,
            )
            # pycocotools reads a results entry's bbox w * h as its area when it has one
            obj = obj.with_declared_area(
                np.array([d["bbox"][2] * d["bbox"][3] if "bbox" in d else np.nan for d in mine])
            )
        else:  # (the boxes' declared areas, w * h, are their own)
            obj = Objects.from_boxes(
                np.array([d["bbox"] for d in mine]).reshape(-1, 4),
                score,
                shape=(h, w),
                plane=pl,
                planes=len(ims),
                box_format="xywh",
                classes=cls,
            )
        out.append((truth, obj, [ids.index(im["id"]) for im in ims]))
    return out


def _rc(bbox) -> list[float]:
    x, y, w, h = bbox
    return [y, x, y + h, x + w]
