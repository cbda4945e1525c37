"""From a matched batch to the per-image inputs of :class:`~torchsar.metrics.coco_compat.CocoState`:
what ``pycocotools`` sees of the same ground truth and detections.

- Categories: class names, as integers by a stable hash (any split of a dataset gives
  the same ids; the ids only order the per-category entries).
- Ground truth: each instance with its class and area (its declared annotation area when the
  dataset gives one, else its pixel count); a plane's ignore pixels become one crowd
  instance per category present in the plane. (pycocotools applies a crowd region to its
  own category only; ignore regions here have none, so they apply to every category: the
  same on one-category data and on data without crowd regions.)
- Detections in the order of the objects (pycocotools breaks score ties by file order);
  class-agnostic objects take the class of the dataset's first category, ``default_class``.
- IoU: ``"segm"``: mask IoU from pixel intersections, crowd as intersection over the
  detection's area; ``"bbox"``: box IoU of the end-exclusive boxes (COCO's ``[x, y, w, h]``),
  crowd against the bounding box of the ignore pixels; detection areas as pycocotools
  computes them (mask pixels, or ``w * h``).
"""

from __future__ import annotations

import hashlib

import numpy as np

from torchsar.metrics.assign import Overlaps, by_plane
from torchsar.metrics.coco_compat import CocoImage
from torchsar.metrics.matching import GroundTruth, box_iou
from torchsar.objects import Objects

__all__ = ["category_id", "coco_images"]


def category_id(name: str) -> int:
    """A stable positive int32 id of a class name.

    Example:
        >>> category_id("ship") == category_id("ship") != category_id("tank")
        True
    """
    digest = hashlib.blake2b(str(name).encode(), digest_size=4).digest()
    return int.from_bytes(digest, "little") & 0x7FFFFFFF


def _ignore_box(ignore: np.ndarray) -> np.ndarray:
    rows, cols = np.flatnonzero(ignore.any(axis=1)), np.flatnonzero(ignore.any(axis=0))
    return np.array([[rows[0], cols[0], rows[-1] + 1, cols[-1] + 1]], dtype=np.float64)


def _box_area(box: np.ndarray) -> np.ndarray:
    return (box[:, 2] - box[:, 0]) * (box[:, 3] - box[:, 1])


def coco_images(
    obj: Objects,
    gt: GroundTruth,
    orders: list[int],
    iou_type: str,
    default_class: str = "target",
) -> list[CocoImage]:
    """One :class:`CocoImage` per plane (see the module docstring).

    Args:
        obj: the batch's objects.
        gt: its ground truth.
        orders: each plane's order key in the dataset.
        iou_type: ``"segm"`` (objects with masks) or ``"bbox"``.
        default_class: the class of objects without one.
    """
    ov = Overlaps(obj, gt) if iou_type == "segm" else None
    det_cls = obj.classes if obj.classes is not None else np.full(len(obj), default_class, object)
    dets, gts = by_plane(obj.plane, obj.planes), by_plane(gt.plane, obj.planes)
    area = gt.declared_area if gt.declared_area is not None else np.full(len(gt), np.nan)
    out = []
    for p in range(obj.planes):
        d, g = dets[p], gts[p]
        cats_g = [category_id(c) for c in gt.classes[g]]
        cats_d = [category_id(c) for c in det_cls[d]]
        g_area = np.where(np.isfinite(area[g]), area[g], gt.area[g]).astype(np.float64)
        if ov is not None:
            iou, on = ov.mask_iou(obj, gt, d, g)
            d_area = obj.area[d].astype(np.float64)
        else:
            iou = box_iou(obj.box[d], gt.box[g])
            d_area = _box_area(obj.box[d])
        crowd_cats = sorted(set(cats_d) | set(cats_g)) if gt.ignore[p].any() else []
        if crowd_cats:
            if ov is None:
                on = box_iou(obj.box[d], _ignore_box(gt.ignore[p]), crowd=True)[:, 0]
            iou = np.concatenate([iou, np.repeat(on[:, None], len(crowd_cats), axis=1)], axis=1)
        n_c = len(crowd_cats)
        out.append(CocoImage(
            order=int(orders[p]),
            gt_category=np.array(cats_g + crowd_cats, np.int64),
            gt_area=np.concatenate([g_area, np.zeros(n_c)]),
            gt_crowd=np.concatenate([np.zeros(g.size, bool), np.ones(n_c, bool)]),
            det_category=np.array(cats_d, np.int64), det_score=obj.score[d],
            det_area=d_area, iou=iou.reshape(d.size, g.size + n_c),
        ))  # fmt: skip
    return out
