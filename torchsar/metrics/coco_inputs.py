"""From a matched batch to the per-image inputs of :class:`~torchsar.metrics.coco_compat.CocoState`:
what ``pycocotools`` sees of the same ground truth and detections.

- Categories: the dataset's category ids where it has them (a COCO file's), else class names
  as integers by a stable hash (any split of a dataset gives the same ids; the ids only order
  the per-category entries).
- Ground truth: each target with its class and area (its declared annotation area when the
  dataset gives one, else its pixel count), overlapping ones as they are; each don't-care
  region becomes a crowd instance of its class, or (a region without a class, such as a
  plane's ignore pixels) one per category present in the image.
- Detections in the order of the objects (pycocotools breaks score ties by file order);
  class-agnostic objects take the class of the dataset's first category, ``default_class``.
- IoU: ``"segm"``: mask IoU from pixel intersections (box IoU for a target given as a box),
  crowd as intersection over the detection's area; ``"bbox"``: box IoU of the end-exclusive
  boxes (COCO's ``[x, y, w, h]``), crowd against the region's box (pycocotools' bbox rule);
  detection areas as pycocotools computes them (mask pixels, or ``w * h``).
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping

import numpy as np

from torchsar.metrics.assign import by_plane, join_pixels, pixel_pairs, region_lists
from torchsar.metrics.coco_compat import CocoImage
from torchsar.metrics.matching import GroundTruth, box_iou
from torchsar.objects import Objects

__all__ = ["category_id", "coco_images"]


def category_id(name: str) -> int:
    """A stable positive int32 id of a class name.

    Examples:
        >>> category_id("ship") == category_id("ship") != category_id("tank")
        True
    """
    digest = hashlib.blake2b(str(name).encode(), digest_size=4).digest()
    return int.from_bytes(digest, "little") & 0x7FFFFFFF


def _box_area(box: np.ndarray) -> np.ndarray:
    return (box[:, 2] - box[:, 0]) * (box[:, 3] - box[:, 1])


def _declared(obj: Objects, d: np.ndarray, own: np.ndarray) -> np.ndarray:
    """The areas of objects ``d`` as pycocotools reads them: declared where given."""
    if obj.declared_area is None:
        return own
    return np.where(np.isfinite(obj.declared_area[d]), obj.declared_area[d], own)


def _pair_values(pairs, pos_a, pos_b, shape, plane_of_a, p) -> np.ndarray:
    """The dense ``shape`` matrix of plane ``p`` from sparse ``(a, b, value)`` pairs."""
    a, b, v = pairs
    out = np.zeros(shape)
    sel = plane_of_a[a] == p if a.size else np.zeros(0, bool)
    out[pos_a[a[sel]], pos_b[b[sel]]] = v[sel]
    return out


def _positions(groups: list[np.ndarray], n: int) -> np.ndarray:
    out = np.zeros(n, np.int64)
    for g in groups:
        out[g] = np.arange(g.size)
    return out


def coco_images(
    obj: Objects,
    gt: GroundTruth,
    orders: list[int],
    iou_type: str,
    default_class: str = "target",
    category_ids: Mapping[str, int] | None = None,
) -> list[CocoImage]:
    """One :class:`CocoImage` per plane (see the module docstring).

    Args:
        obj: the batch's objects.
        gt: its ground truth.
        orders: each plane's order key in the dataset.
        iou_type: ``"segm"`` (objects with masks) or ``"bbox"``.
        default_class: the class of objects without one.
        category_ids: the dataset's category id of each class name (default: a hash).
    """

    def cat(name) -> int:
        name = str(name)
        known = category_ids and name in category_ids
        return int(category_ids[name]) if known else category_id(name)

    det_cls = obj.classes if obj.classes is not None else np.full(len(obj), default_class, object)
    dets, gts = by_plane(obj.plane, obj.planes), by_plane(gt.plane, obj.planes)
    regs = by_plane(gt.crowd.plane, obj.planes)
    pos_d, pos_g = _positions(dets, len(obj)), _positions(gts, len(gt))
    pos_k = _positions(regs, len(gt.crowd))
    area = gt.coco_area
    segm = iou_type == "segm"
    if segm:
        inter = pixel_pairs(obj, gt)
        union = obj.area[inter[0]] + gt.area[inter[1]] - inter[2]
        real = (inter[0], inter[1], inter[2] / np.maximum(union, 1))
        r_owner, r_pix = region_lists(gt)
        owner, idx = obj.pixel_lists()
        jd, jk, jn = join_pixels(owner, idx, r_owner, r_pix)
        on_region = (jd, jk, jn / np.maximum(obj.area[jd], 1))
    out = []
    for p in range(obj.planes):
        d, g, k = dets[p], gts[p], regs[p]
        cats_g = [cat(c) for c in gt.classes[g]]
        cats_d = [cat(c) for c in det_cls[d]]
        if segm:
            iou = _pair_values(real, pos_d, pos_g, (d.size, g.size), obj.plane, p)
            boxed = ~gt.has_mask[g]  # a target given as a box: box IoU
            if boxed.any():
                iou[:, boxed] = box_iou(obj.box[d], gt.box[g[boxed]])
            on = _pair_values(on_region, pos_d, pos_k, (d.size, k.size), obj.plane, p)
            d_area = _declared(obj, d, obj.area[d].astype(np.float64))
        else:
            iou = box_iou(obj.box[d], gt.box[g])
            on = box_iou(obj.box[d], gt.crowd.box[k], crowd=True)
            d_area = _declared(obj, d, _box_area(obj.box[d]))
        crowd_cols, crowd_cats = [], []
        present = sorted(set(cats_d) | set(cats_g))
        for j, r in enumerate(k):
            c = gt.crowd.classes[r]
            for cc in present if c is None else [cat(c)]:
                crowd_cols.append(j)
                crowd_cats.append(cc)
        n_c = len(crowd_cols)
        iou = np.concatenate([iou, on[:, crowd_cols]], axis=1) if n_c else iou
        out.append(
            CocoImage(
                order=int(orders[p]),
                gt_category=np.array(cats_g + crowd_cats, np.int64),
                gt_area=np.concatenate([area[g], np.zeros(n_c)]),
                gt_crowd=np.concatenate([np.zeros(g.size, bool), np.ones(n_c, bool)]),
                det_category=np.array(cats_d, np.int64),
                det_score=obj.score[d],
                det_area=d_area,
                iou=iou.reshape(d.size, g.size + n_c),
            )
        )
    return out
