"""Pure scoring: pixel counts, one-to-one object matching, additive object states (AP, FROC,
P/R/F1, breakdowns, bootstrap), the pixel ROC, and despeckling quality.

Image-formation metrics (focus of a formed image, fidelity to a known scene or phase error)
live with imaging: :mod:`torchsar.imaging.focus` and :mod:`torchsar.imaging.fidelity`."""

from torchsar.metrics.assign import BatchMatch, match_batch
from torchsar.metrics.counts import (
    ObjectCounts,
    PixelCounts,
    label_components,
    object_counts,
    pixel_counts,
)
from torchsar.metrics.curves import coco_ap, partial_auc, pd_at_fa
from torchsar.metrics.despeckling import (
    edge_preservation,
    edge_ratio,
    enl,
    psnr,
    ratio_moments,
    ssim,
)
from torchsar.metrics.matching import GroundTruth, Matching, box_iou, greedy_match, ground_truth
from torchsar.metrics.object_state import ImageInfo, ObjectState
from torchsar.metrics.roc import RocAccumulator

__all__ = [
    "BatchMatch",
    "GroundTruth",
    "ImageInfo",
    "Matching",
    "ObjectCounts",
    "ObjectState",
    "PixelCounts",
    "RocAccumulator",
    "box_iou",
    "coco_ap",
    "edge_preservation",
    "edge_ratio",
    "enl",
    "greedy_match",
    "ground_truth",
    "label_components",
    "match_batch",
    "object_counts",
    "partial_auc",
    "pd_at_fa",
    "pixel_counts",
    "psnr",
    "ratio_moments",
    "ssim",
]
