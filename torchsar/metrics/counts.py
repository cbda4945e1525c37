"""Pixel- and object-level detection scores against ground-truth masks.

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
from torch import Tensor

from torchsar._checks import check_same_shape
from torchsar.errors import InputTypeError
from torchsar.objects.components import label_components

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


def pixel_counts(pred: Tensor, target: Tensor, *, ignore: Tensor | None = None) -> PixelCounts:
    """Count detected target and clutter pixels.

    Args:
        pred: bool detections, any shape.
        target: bool ground-truth target pixels, same shape.
        ignore: optional bool don't-care pixels, same shape.

    Examples:
        >>> p = torch.tensor([True, True, False, False])
        >>> t = torch.tensor([True, False, True, False])
        >>> c = pixel_counts(p, t); (c.pd, c.pfa)
        (0.5, 0.5)
    """
    _as_bool(pred, "pred")
    _as_bool(target, "target")
    check_same_shape(pred, target, "pred", "target")
    if ignore is not None and bool(_as_bool(ignore, "ignore").any()):
        care = ~ignore
        pred, target, n_care = pred & care, target & care, int(torch.count_nonzero(care))
    else:
        n_care = pred.numel()
    tp, detected = int(torch.count_nonzero(pred & target)), int(torch.count_nonzero(pred))
    targets = int(torch.count_nonzero(target))
    return PixelCounts(tp=tp, fp=detected - tp, targets=targets, clutter=n_care - targets)


def _global_ids(inst: np.ndarray) -> np.ndarray:
    """Instance ids made unique across images ``(N, H, W)`` (0 stays background)."""
    per_image = inst.reshape(inst.shape[0], -1).max(axis=1, initial=0)
    offset = np.concatenate([[0], np.cumsum(per_image)[:-1]])
    return np.where(inst > 0, inst + offset[:, None, None], 0)


def _batch_objects(
    labels: np.ndarray, n: int, inst: np.ndarray, ignore: np.ndarray | None
) -> ObjectCounts:
    """Object counts of a stack of images from component labels and global instance ids."""
    m = int(inst.max(initial=0))
    lab, ids = labels.ravel(), inst.ravel()
    both = (lab > 0) & (ids > 0)
    pairs, overlap = np.unique(lab[both].astype(np.int64) * (m + 1) + ids[both], return_counts=True)
    pair_comp, pair_inst = pairs // (m + 1), pairs % (m + 1)
    comp_area = np.bincount(lab, minlength=n + 1)
    inst_area = np.bincount(ids, minlength=m + 1)
    inter = np.bincount(pair_inst, weights=overlap, minlength=m + 1)
    union_comp = np.bincount(pair_inst, weights=comp_area[pair_comp], minlength=m + 1)
    detected = np.bincount(pair_inst, minlength=m + 1)[1:] > 0
    iou = (inter / np.maximum(inst_area + union_comp - inter, 1))[1:]
    lonely = np.ones(n + 1, bool)
    lonely[pair_comp] = False
    lonely[0] = False
    if ignore is not None:
        lonely &= np.bincount(lab[~ignore.ravel()], minlength=n + 1) > 0
    return ObjectCounts(
        images=int(labels.shape[0]),
        instances=int((inst_area[1:] > 0).sum()),
        detected=int(detected.sum()),
        false_alarms=int(lonely.sum()),
        fragments=int(pair_comp.size),
        iou_sum=float(iou[detected].sum()),
    )


def object_counts(
    pred: Tensor,
    instances: Tensor,
    *,
    ignore: Tensor | None = None,
    connectivity: int = 2,
) -> ObjectCounts:
    """Object-level counts for a batch ``(B, C, H, W)`` (each ``(b, c)`` plane is an image).

    Args:
        pred: bool detections.
        instances: int ground-truth instance ids (0 = background), same shape.
        ignore: optional bool don't-care pixels.
        connectivity: 1 (4-connected) or 2 (8-connected) components.

    Examples:
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
    if p.shape[0] == 0:
        return ObjectCounts()
    labels, n = label_components(p, connectivity)
    return _batch_objects(labels, n, _global_ids(g), ig)
