"""Instance-id maps: colour (or grey level) per instance, 0 / black = none."""

from __future__ import annotations

import numpy as np

from torchsar.io.errors import FileFormatError

__all__ = ["decode_id_map"]

LOSSY_EXTS = (".jpg", ".jpeg")


def decode_id_map(a: np.ndarray, path: str) -> np.ndarray:
    """Instance ids ``1..K`` (int32, 0 = none) from a grey or colour id map.

    A grey map is taken as the ids themselves, renumbered ``1..K`` in order of first
    appearance (raster order). In a colour map each distinct colour is one instance, black
    is background, alpha is ignored; ids follow first appearance too. Colours are never
    averaged to grey (two colours with the same mean would merge).

    Args:
        a: ``(H, W)`` or ``(H, W, C)`` decoded id map.
        path: its file, named in errors; a lossy (JPEG) id map is refused.

    Raises:
        FileFormatError: a JPEG id map (compression invents colours) or a bad layout.

    Examples:
        >>> m = np.zeros((2, 3, 3), np.uint8); m[0, 2] = (9, 0, 0); m[1, 0] = (0, 0, 7)
        >>> decode_id_map(m, "ids.png").tolist()
        [[0, 0, 1], [2, 0, 0]]
    """
    if str(path).lower().endswith(LOSSY_EXTS):
        raise FileFormatError(path, "is a JPEG; an instance-id map must be lossless (PNG/TIFF)")
    if a.ndim == 3 and a.shape[2] in (2, 4):
        a = a[..., :-1]
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim == 2:
        keys = a.astype(np.int64)
    elif a.ndim == 3 and a.shape[2] == 3:
        c = a.astype(np.int64)
        keys = (c[..., 0] << 42) | (c[..., 1] << 21) | c[..., 2]
    else:
        raise FileFormatError(path, f"has shape {a.shape}; expected (H, W) or (H, W, 3)")
    flat = keys.ravel()
    values, first, inverse = np.unique(flat, return_index=True, return_inverse=True)
    order = np.argsort(np.where(values == 0, -1, first), kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    ids = rank[inverse] + (0 if (values == 0).any() else 1)
    return ids.reshape(keys.shape).astype(np.int32)
