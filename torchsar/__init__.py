"""torchsar: batched PyTorch SAR target detection and a dataset-scale evaluator."""

from torchsar import (
    cfar,
    errors,
    imaging,
    io,
    metrics,
    motion,
    objects,
    region,
    sar,
    simulate,
    speckle,
    tiling,
    windows,
)

__version__ = "0.1.0"

__all__ = [
    "__version__",
    "cfar",
    "errors",
    "imaging",
    "io",
    "metrics",
    "motion",
    "objects",
    "region",
    "sar",
    "simulate",
    "speckle",
    "tiling",
    "windows",
]
