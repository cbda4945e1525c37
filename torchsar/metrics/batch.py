"""What matching a batch gives (:class:`BatchMatch`), shared by every matching rule (the
overlap rules of :mod:`torchsar.metrics.assign`, the distance rule of
:mod:`torchsar.metrics.points`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BatchMatch", "by_plane"]


@dataclass(frozen=True)
class BatchMatch:
    """Assignments of one batch.

    Attributes:
        ap: int ``(A, T, M)`` per area range of :data:`AP_AREAS` and COCO IoU threshold:
            matched target index, -1 false, -2 ignored (IoU of :attr:`Matching.iou_kind`).
        op: int ``(M,)`` the same under the matching rule.
        op_iou: float ``(M,)`` IoU of each detection with the target it matched under the
            rule (0 when unmatched).
        gt_score: float ``(G,)`` score of the detection that matched each target under the
            rule (``-inf``: missed).
        overlaps: int ``(G,)`` number of detections touching each target (fragmentation).
        gt_det: int ``(G,)`` index of that detection (-1: missed).
        ap_kind: ``"iou"``, ``"distance"`` or ``"none"`` (points under an IoU rule).
        by_class: whether detections were matched within their class.
    """

    ap: np.ndarray
    op: np.ndarray
    op_iou: np.ndarray
    gt_score: np.ndarray
    overlaps: np.ndarray
    gt_det: np.ndarray
    ap_kind: str = "iou"
    by_class: bool = False


def by_plane(plane: np.ndarray, n_planes: int) -> list[np.ndarray]:
    """Indices of the items of each plane (``plane``: each item's plane), in item order."""
    order = np.argsort(plane, kind="stable")
    cuts = np.searchsorted(plane[order], np.arange(n_planes + 1))
    return [order[cuts[p] : cuts[p + 1]] for p in range(n_planes)]
