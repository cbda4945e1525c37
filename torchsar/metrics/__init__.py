"""Pure scoring functions: detection counts, ROC accumulation, despeckling quality."""

from torchsar.metrics.despeckling import (
    edge_preservation,
    edge_ratio,
    enl,
    psnr,
    ratio_moments,
    ssim,
)
from torchsar.metrics.detection import (
    ObjectCounts,
    PixelCounts,
    label_components,
    object_counts,
    pixel_counts,
)
from torchsar.metrics.roc import (
    RocAccumulator,
    default_object_grid,
    default_pixel_grid,
    merged_grid,
)

__all__ = [
    "ObjectCounts",
    "PixelCounts",
    "RocAccumulator",
    "default_object_grid",
    "default_pixel_grid",
    "edge_preservation",
    "edge_ratio",
    "enl",
    "label_components",
    "merged_grid",
    "object_counts",
    "pixel_counts",
    "psnr",
    "ratio_moments",
    "ssim",
]
