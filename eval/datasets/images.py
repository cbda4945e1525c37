"""Image and label files of the folder-like datasets: samples, label maps, sizes."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from torchsar.io import (
    FileFormatError,
    raster_shape,
    read_raster,
    single_channel,
)
from torchsar_eval.datasets.spec import DEFAULT_MAX_PIXELS
from torchsar_eval.errors import EvalError

__all__ = ["LABELS", "check_same_size", "read_image", "read_labels", "read_samples"]

LABELS = (0, 1, 2)  # clutter, target, shadow / ignore
JPEG_TOLERANCE = 8  # grey JPEG saved as RGB: lossy chroma may differ by a few levels


def read_samples(path: Path, sample_type: str, *, max_pixels: int) -> np.ndarray:
    """``(H, W)`` samples as stored: real grey, or complex (complex TIFF, or a real raster
    with two channels I, Q when ``sample_type`` is ``complex``)."""
    a = read_raster(path, max_pixels=max_pixels)
    if sample_type == "complex" and not np.iscomplexobj(a):
        if a.ndim != 3 or a.shape[2] != 2:
            raise FileFormatError(
                path, f"is real with shape {a.shape}; type=complex needs complex or (H, W, 2) I/Q"
            )
        return a[..., 0].astype(np.float32) + 1j * a[..., 1].astype(np.float32)
    if np.iscomplexobj(a):
        return a if a.ndim == 2 else single_channel(a, str(path))
    lossy = path.suffix.lower() in (".jpg", ".jpeg")
    return single_channel(a, str(path), tolerance=JPEG_TOLERANCE if lossy else 0)


def read_labels(path: Path, *, max_pixels: int) -> np.ndarray:
    """A ``0 / 1 / 2`` label map (grey, equal-channel RGB, or palette indices)."""
    a = single_channel(read_raster(path, max_pixels=max_pixels), str(path))
    if a.dtype.kind not in "uib":
        raise FileFormatError(path, f"label map has dtype {a.dtype}; expected integer labels")
    bad = np.setdiff1d(np.unique(a), LABELS)
    if bad.size:
        raise FileFormatError(
            path, f"has labels {bad.tolist()[:10]}; expected 0 clutter, 1 target, 2 shadow/ignore"
        )
    return a.astype(np.uint8)


def check_same_size(image: Path, other: Path) -> None:
    """Compare the header sizes of an image and its label file before decoding either."""
    si, so = raster_shape(image)[:2], raster_shape(other)[:2]
    if si != so:
        raise FileFormatError(other, f"is {so[1]}x{so[0]} but image {image} is {si[1]}x{si[0]}")


def read_image(path: Path, *, max_pixels: int = DEFAULT_MAX_PIXELS) -> np.ndarray:
    """A grey image as a 2-D float64 array (colour refused, never averaged)."""
    try:
        return np.asarray(read_samples(Path(path), "display", max_pixels=max_pixels), float)
    except FileFormatError as exc:
        raise EvalError(f"cannot read image {exc}") from exc
