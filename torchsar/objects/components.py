"""Connected components of stacked bool planes (labels unique across the stack)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from torchsar._checks import OptionError

__all__ = ["label_components"]

_STRUCTURES = {1: ndimage.generate_binary_structure(2, 1), 2: np.ones((3, 3), bool)}


def label_components(mask: np.ndarray, connectivity: int = 2) -> tuple[np.ndarray, int]:
    """Connected components of a bool array; the last two axes are the image plane, leading
    axes index separate images (labels are unique across the whole array).

    Args:
        mask: bool array ``(..., H, W)``.
        connectivity: 1 = 4-connected, 2 = 8-connected.

    Returns:
        ``(labels, n)``: int32 labels ``1..n`` (0 = background) and the count.

    Raises:
        OptionError: connectivity other than 1 or 2.

    Example:
        >>> m = np.array([[1, 0, 0], [0, 1, 0]], bool)
        >>> label_components(m, 2)[1], label_components(m, 1)[1]
        (1, 2)
    """
    if connectivity not in _STRUCTURES or isinstance(connectivity, bool):
        raise OptionError(
            f"connectivity must be 1 (4-connected) or 2 (8-connected), got {connectivity!r}"
        )
    if mask.size == 0:
        return np.zeros(mask.shape, np.int32), 0
    plane = _STRUCTURES[connectivity]
    structure = np.zeros((3,) * (mask.ndim - 2) + (3, 3), bool)
    structure[(1,) * (mask.ndim - 2)] = plane
    labels, n = ndimage.label(mask, structure=structure)
    return labels, int(n)
