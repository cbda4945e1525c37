"""Pixel- and object-level detection scores against ground-truth masks (DESIGN §5).

Counts are plain integers held in small dataclasses that add up (``a + b``), so scores over
a dataset are exact whatever the batching, sharding or worker split. Ratios are computed
from the summed counts, never averaged per batch.

Pixel level: ``Pd = TP / target pixels``; ``Pfa = FP / clutter pixels``; ignored pixels
(e.g. MSTAR radar shadow) count as neither.

Object level: detected pixels are grouped into connected components (8-connected by
default). A ground-truth instance is *detected* when some component overlaps it; a
component overlapping no instance is a *false alarm* unless all its pixels are ignored;
*fragmentation* is the number of components overlapping a detected instance, averaged over
detected instances; ``FoM = N_detected / (N_false_alarms + N_instances)``; the IoU of a
detected instance is that of the instance and the union of the components overlapping it.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import torch
from scipy import ndimage
from torch import Tensor

from torchsar._checks import InputTypeError, check_same_shape

__all__ = ["ObjectCounts", "PixelCounts", "label_components", "object_counts", "pixel_counts"]


class _Additive:
    """Mixin: field-wise addition of count dataclasses."""

    def __add__(self, other):  # type: ignore[no-untyped-def]
        if not isinstance(other, type(self)):
            return NotImplemented
        return type(self)(
            **{f.name: getattr(self, f.name) + getattr(other, f.name) for f in fields(self)}
        )


def _ratio(num: float, den: float) -> float:
    return float(num) / float(den) if den else float("nan")


@dataclass(frozen=True)
class PixelCounts(_Additive):
    """Pixel confusion counts: detected target pixels, detected clutter pixels, totals."""

    tp: int = 0
    fp: int = 0
    targets: int = 0
    clutter: int = 0

    @property
    def pd(self) -> float:
        """``TP / target pixels`` (NaN when there are no target pixels)."""
        return _ratio(self.tp, self.targets)

    @property
    def pfa(self) -> float:
        """``FP / clutter pixels`` (NaN when there are no clutter pixels)."""
        return _ratio(self.fp, self.clutter)


@dataclass(frozen=True)
class ObjectCounts(_Additive):
    """Object-level counts summed over images."""

    images: int = 0
    instances: int = 0
    detected: int = 0
    false_alarms: int = 0
    fragments: int = 0
    iou_sum: float = 0.0

    @property
    def pd(self) -> float:
        """Fraction of ground-truth instances detected."""
        return _ratio(self.detected, self.instances)

    @property
    def false_alarms_per_image(self) -> float:
        return _ratio(self.false_alarms, self.images)

    @property
    def fragmentation(self) -> float:
        """Components per detected instance (1 = every detected object is one component)."""
        return _ratio(self.fragments, self.detected)

    @property
    def fom(self) -> float:
        """Figure of merit ``N_detected / (N_false_alarms + N_instances)``."""
        return _ratio(self.detected, self.false_alarms + self.instances)

    @property
    def mean_iou(self) -> float:
        """Mean IoU over detected instances."""
        return _ratio(self.iou_sum, self.detected)


def _as_bool(t: Tensor, name: str) -> Tensor:
    if not isinstance(t, Tensor) or t.dtype != torch.bool:
        got = t.dtype if isinstance(t, Tensor) else type(t).__name__
        raise InputTypeError(f"{name} must be a bool tensor, got {got}")
    return t


def pixel_counts(pred: Tensor, target: Tensor, ignore: Tensor | None = None) -> PixelCounts:
    """Count detected target and clutter pixels.

    Args:
        pred: bool detections, any shape.
        target: bool ground-truth target pixels, same shape.
        ignore: optional bool don't-care pixels, same shape.

    Example:
        >>> p = torch.tensor([True, True, False, False])
        >>> t = torch.tensor([True, False, True, False])
        >>> c = pixel_counts(p, t); (c.pd, c.pfa)
        (0.5, 0.5)
    """
    _as_bool(pred, "pred")
    _as_bool(target, "target")
    check_same_shape(pred, target, "pred", "target")
    care = torch.ones_like(pred) if ignore is None else ~_as_bool(ignore, "ignore")
    tgt = target & care
    clu = ~target & care
    return PixelCounts(
        tp=int((pred & tgt).sum()),
        fp=int((pred & clu).sum()),
        targets=int(tgt.sum()),
        clutter=int(clu.sum()),
    )


_STRUCTURES = {1: ndimage.generate_binary_structure(2, 1), 2: np.ones((3, 3), bool)}


def label_components(mask: np.ndarray, connectivity: int = 2) -> tuple[np.ndarray, int]:
    """Connected components of a 2-D bool array (1 = 4-, 2 = 8-connectivity)."""
    labels, n = ndimage.label(mask, structure=_STRUCTURES[connectivity])
    return labels, int(n)


def _image_objects(
    labels: np.ndarray, n: int, inst: np.ndarray, ignore: np.ndarray | None
) -> ObjectCounts:
    """Object counts of one image from its component labels and instance ids."""
    m = int(inst.max()) if inst.size else 0
    ids = np.unique(inst[inst > 0])
    overlap = np.bincount(
        (labels.astype(np.int64) * (m + 1) + inst).ravel(), minlength=(n + 1) * (m + 1)
    ).reshape(n + 1, m + 1)
    comp_area = overlap.sum(axis=1)
    hits = overlap[1:, 1:] > 0  # (components, instance ids)
    per_inst = hits[:, ids - 1] if ids.size else np.zeros((n, 0), bool)
    detected = per_inst.any(axis=0)
    inter = (overlap[1:, 1:][:, ids - 1] * per_inst).sum(axis=0) if ids.size else np.zeros(0)
    union_comp = (comp_area[1:, None] * per_inst).sum(axis=0) if ids.size else np.zeros(0)
    inst_area = overlap[:, 1:].sum(axis=0)[ids - 1] if ids.size else np.zeros(0)
    iou = inter / np.maximum(inst_area + union_comp - inter, 1)
    lonely = ~hits.any(axis=1)
    if ignore is not None and n:
        outside = np.bincount(labels[~ignore].ravel(), minlength=n + 1)[1:] > 0
        lonely &= outside
    return ObjectCounts(
        images=1,
        instances=int(ids.size),
        detected=int(detected.sum()),
        false_alarms=int(lonely.sum()),
        fragments=int(per_inst[:, detected].sum()),
        iou_sum=float(iou[detected].sum()),
    )


def object_counts(
    pred: Tensor,
    instances: Tensor,
    ignore: Tensor | None = None,
    *,
    connectivity: int = 2,
) -> ObjectCounts:
    """Object-level counts for a batch ``(B, C, H, W)`` (each ``(b, c)`` plane is an image).

    Args:
        pred: bool detections.
        instances: int ground-truth instance ids (0 = background), same shape.
        ignore: optional bool don't-care pixels.
        connectivity: 1 (4-connected) or 2 (8-connected) components.

    Example:
        >>> inst = torch.zeros(1, 1, 6, 6, dtype=torch.int32); inst[0, 0, 1:3, 1:3] = 1
        >>> pred = torch.zeros(1, 1, 6, 6, dtype=torch.bool); pred[0, 0, 1:3, 1:3] = True
        >>> pred[0, 0, 5, 5] = True
        >>> c = object_counts(pred, inst); (c.detected, c.false_alarms, c.mean_iou)
        (1, 1, 1.0)
    """
    _as_bool(pred, "pred")
    check_same_shape(pred, instances, "pred", "instances")
    p = pred.detach().cpu().numpy().reshape(-1, *pred.shape[-2:])
    g = instances.detach().cpu().numpy().astype(np.int64).reshape(p.shape)
    ig = None if ignore is None else _as_bool(ignore, "ignore").cpu().numpy().reshape(p.shape)
    total = ObjectCounts()
    for i in range(p.shape[0]):
        labels, n = label_components(p[i], connectivity)
        total = total + _image_objects(labels, n, g[i], None if ig is None else ig[i])
    return total
