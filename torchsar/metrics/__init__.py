"""Pure scoring functions: pixel and object detection counts, ROC accumulation."""

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
    "label_components",
    "merged_grid",
    "object_counts",
    "pixel_counts",
]
