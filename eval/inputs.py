"""What a training loop hands to :meth:`~torchsar_eval.Evaluator.update`, as the scorer needs
it: per image, torchvision-style dicts of tensors or arrays (or typed
:class:`~torchsar_eval.items.Item` / :class:`~torchsar_eval.items.Targets`) become
:class:`~torchsar_eval.items.Targets` with an :class:`~torchsar_eval.items.ImageMeta`, and
the predictions :class:`~torchsar.objects.Objects`.

- targets: ``{"boxes": (G, 4), "labels": (G,), "masks": (G, H, W) (optional), "iscrowd":
  (G,) (optional: crowd targets become don't-care regions of their class), "area": (G,)
  (optional, COCO's declared areas), "image_id" (optional: the image's order key), "name"
  (optional), "size": (H, W) (optional)}``;
- predictions: ``{"boxes": (M, 4), "scores": (M,), "labels": (M,) (optional: without, the
  detections are class-agnostic), "masks": (M, H, W) or (M, 1, H, W) (optional, cut at
  ``mask_threshold`` when not boolean), "points": (M, 2) (row, col; instead of boxes)}``.

Boxes are in ``box_format``: ``"xyxy"`` (torchvision, the default), ``"xywh"`` (COCO) or
``"rc"`` (torchsar's ``(r0, c0, r1, c1)``). Integer labels are named by ``categories`` (an
``{id: name}`` dict) where given, else by their number.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from torchsar.objects import Objects
from torchsar_eval.errors import EvalError
from torchsar_eval.items import ImageMeta, Item, Targets, extent

__all__ = ["BOX_FORMATS", "objects_from", "truth_from"]

BOX_FORMATS = ("xyxy", "xywh", "rc")


def _array(v, dtype=None) -> np.ndarray:
    """A tensor or array-like as a numpy array (on the CPU)."""
    if hasattr(v, "detach"):
        v = v.detach().cpu().numpy()
    return np.asarray(v) if dtype is None else np.asarray(v, dtype=dtype)


def _rc(boxes, fmt: str, what: str) -> np.ndarray:
    """Boxes in ``fmt`` as ``(r0, c0, r1, c1)``."""
    if fmt not in BOX_FORMATS:
        raise EvalError(f"{{opt:box_format}}{fmt!r}: expected one of {', '.join(BOX_FORMATS)}")
    b = _array(boxes, np.float64).reshape(-1, 4) if np.size(_array(boxes)) else np.zeros((0, 4))
    if fmt == "rc":
        return b
    x0, y0, a, c = b.T
    x1, y1 = (a, c) if fmt == "xyxy" else (x0 + a, y0 + c)
    out = np.stack([y0, x0, y1, x1], axis=1)
    if not np.isfinite(out).all() or (out[:, 2:] < out[:, :2]).any():
        raise EvalError(f"{what} boxes must be finite with x1 >= x0 and y1 >= y0 ({fmt})")
    return out


def _names(labels, n: int, categories: Mapping | None, what: str) -> list[str] | None:
    if labels is None:
        return None
    values = _array(labels).reshape(-1).tolist()
    if len(values) != n:
        raise EvalError(f"{what} labels must hold one label per box ({n}), got {len(values)}")
    if categories:
        unknown = [v for v in values if v not in categories and str(v) not in categories]
        if unknown:
            raise EvalError(
                f"{what} label {unknown[0]!r} is not one of the categories {sorted(categories)}"
            )
        return [str(categories.get(v, categories.get(str(v)))) for v in values]
    return [str(v) for v in values]


def _mask_pixels(masks, n: int, threshold: float, what: str) -> tuple[list, tuple[int, int]]:
    m = _array(masks)
    if m.ndim == 4:
        m = m[:, 0]
    if m.ndim != 3 or m.shape[0] != n:
        raise EvalError(
            f"{what} masks must be (N, H, W) with one mask per box ({n}), got shape {m.shape}"
        )
    m = m if m.dtype == bool else m > threshold
    return [np.flatnonzero(x.reshape(-1)) for x in m], (int(m.shape[1]), int(m.shape[2]))


def truth_from(
    target,
    k: int,
    *,
    box_format: str = "xyxy",
    categories=None,
    mask_threshold: float = 0.5,
    seen: tuple[int, int] | None = None,
) -> tuple[Targets, ImageMeta]:
    """One image's ground truth (see the module docstring); ``k``: its default order;
    ``seen``: the image's ``(H, W)`` as its pixels or predicted masks show it, for targets
    that give none (no masks, no ``size``; else the boxes' extent)."""
    if isinstance(target, Item):
        shape = target.meta.shape or (target.image is None and seen) or target.shape
        return target.targets, replace(target.meta, shape=tuple(shape))
    if isinstance(target, Targets):
        return target, ImageMeta(str(k), index=k, shape=seen or extent(target))
    if not isinstance(target, Mapping) or "boxes" not in target:
        raise EvalError(
            f"target {k} must be a dict with 'boxes' (and 'labels', 'masks', "
            f"'iscrowd', ...), a Targets or an Item, got {type(target).__name__}"
        )
    what = f"target {k}"
    boxes = _rc(target["boxes"], box_format, what)
    n = boxes.shape[0]
    names = _names(target.get("labels"), n, categories, what) or ["target"] * n
    pixels, shape = [None] * n, None
    if target.get("masks") is not None:
        pixels, shape = _mask_pixels(target["masks"], n, mask_threshold, what)
    crowd = (
        _array(target["iscrowd"]).reshape(-1).astype(bool)
        if target.get("iscrowd") is not None
        else np.zeros(n, bool)
    )
    area = None if target.get("area") is None else _array(target["area"], np.float64).reshape(-1)
    real = np.flatnonzero(~crowd)
    crowd_idx = np.flatnonzero(crowd)
    t = Targets.build(
        boxes[real],
        classes=[names[i] for i in real],
        pixels=[pixels[i] for i in real],
        areas=None if area is None else area[real],
        crowd_boxes=boxes[crowd_idx],
        crowd_classes=[names[i] for i in crowd_idx],
        crowd_pixels=[pixels[i] for i in crowd_idx],
    )
    if target.get("size") is not None:
        shape = tuple(int(v) for v in _array(target["size"]).reshape(-1)[:2])
    image_id = target.get("image_id")
    index = k if image_id is None else int(_array(image_id).reshape(-1)[0])
    name = str(target.get("name", index))
    return t, ImageMeta(name, index=index, shape=shape or seen or extent(t))


def seen_shape(prediction, image) -> tuple[int, int] | None:
    """An image's ``(H, W)`` from its pixels (``image``, ``(C, H, W)`` or ``(H, W)``), else
    from its predicted masks (``(N, H, W)``); ``None`` when neither is given."""
    if image is not None:
        return (int(image.shape[-2]), int(image.shape[-1]))
    masks = prediction.get("masks") if isinstance(prediction, Mapping) else None
    if masks is not None and len(getattr(masks, "shape", ())) >= 2:
        return (int(masks.shape[-2]), int(masks.shape[-1]))
    return None


def objects_from(
    predictions: Sequence,
    shape: tuple[int, int],
    *,
    box_format: str = "xyxy",
    categories=None,
    threshold: float | None = None,
    mask_threshold: float = 0.5,
) -> Objects:
    """The predictions of a stack of images of ``shape`` (one dict per image, see the module
    docstring) as one :class:`~torchsar.objects.Objects` (plane ``k``: image ``k``)."""
    boxes, scores, names, pixels, points, planes = [], [], [], [], [], []
    kinds = set()
    for k, p in enumerate(predictions):
        what = f"prediction {k}"
        if not isinstance(p, Mapping) or "scores" not in p:
            raise EvalError(
                f"{what} must be a dict with 'scores' and 'boxes', 'masks' or "
                f"'points', got {type(p).__name__}"
            )
        s = _array(p["scores"], np.float64).reshape(-1)
        n = s.size
        if p.get("points") is not None:
            kinds.add("point")
            points.append(_array(p["points"], np.float64).reshape(n, 2))
        else:
            kinds.add("mask" if p.get("masks") is not None else "box")
            boxes.append(_rc(p["boxes"], box_format, what) if "boxes" in p else np.zeros((n, 4)))
            if p.get("masks") is not None:
                pixels += _mask_pixels(p["masks"], n, mask_threshold, what)[0]
        got = _names(p.get("labels"), n, categories, what)
        names.append(got)
        scores.append(s)
        planes.append(np.full(n, k, np.int64))
    if len(kinds) > 1:
        raise EvalError(
            f"predictions mix {' and '.join(sorted(kinds))}: give every image the same kind"
        )
    if any(n is None for n in names) and not all(n is None for n in names):
        raise EvalError(
            "some predictions have labels and others not: give every image "
            "labels, or none (class-agnostic)"
        )
    cls = None if not names or names[0] is None else [c for ns in names for c in ns]
    score = np.concatenate(scores) if scores else np.zeros(0)
    plane = np.concatenate(planes) if planes else np.zeros(0, np.int64)
    common = {"plane": plane, "planes": len(predictions), "threshold": threshold, "classes": cls}
    kind = kinds.pop() if kinds else "box"
    if kind == "point":
        return Objects.from_points(
            np.concatenate(points).reshape(-1, 2), score, shape=shape, **common
        )
    if kind == "mask":
        return Objects.from_pixel_lists(pixels, score, shape=shape, **common)
    return Objects.from_boxes(
        np.concatenate(boxes).reshape(-1, 4) if boxes else np.zeros((0, 4)),
        score,
        shape=shape,
        **common,
    )
