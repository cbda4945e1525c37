"""One channel out of a stored raster, never by averaging channels that disagree."""

from __future__ import annotations

import numpy as np

from torchsar.io.errors import FileFormatError

__all__ = ["single_channel"]


def single_channel(a: np.ndarray, path: str, *, tolerance: float = 0) -> np.ndarray:
    """The ``(H, W)`` plane of a grey raster stored as ``(H, W)`` or ``(H, W, C)``.

    Grey saved as RGB (or grey + alpha, RGB + alpha) is accepted when its colour channels
    agree within ``tolerance`` (0 for labels and lossless images; a few levels for JPEG,
    whose chroma is lossy); the first channel is returned. Anything else is refused:
    averaging would silently change labels (a label in the red channel only would become 0).

    Args:
        a: the decoded raster.
        path: the file it came from (named in the error).
        tolerance: largest accepted difference between colour channels.

    Raises:
        FileFormatError: colour channels that disagree, or an unexpected layout.

    Examples:
        >>> single_channel(np.dstack([np.eye(2)] * 3), "x.png").tolist()
        [[1.0, 0.0], [0.0, 1.0]]
    """
    if a.ndim == 2:
        return a
    if a.ndim != 3 or a.shape[2] not in (2, 3, 4):
        raise FileFormatError(path, f"has shape {a.shape}; expected (H, W) or (H, W, 1-4)")
    colour = a[..., : 1 if a.shape[2] == 2 else 3]
    spread = colour.max(axis=2).astype(np.float64) - colour.min(axis=2)
    if spread.size and spread.max() > tolerance:
        n = int((spread > tolerance).sum())
        raise FileFormatError(
            path,
            f"has {a.shape[2]} channels that differ at {n} pixels (a colour image); expected "
            "grey (one channel, or equal channels)",
        )
    return a[..., 0]
