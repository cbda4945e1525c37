"""Step a–b: candidate seeds (local maxima of the despeckled image), brightest first."""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as nnf
from torch import Tensor

__all__ = ["local_maxima", "seed_order"]


def local_maxima(f: Tensor, window: int = 5) -> Tensor:
    """Pixels equal to the maximum of their ``window x window`` neighbourhood (seed eq. 3).

    Cells outside the image do not count (a border pixel is compared with the cells that
    exist). Plateaus give several equal seeds; the growth order makes that harmless.

    Args:
        f: real ``(B, C, H, W)`` image (the despeckled image F).
        window: odd neighbourhood width (5 in the paper).

    Returns:
        bool ``(B, C, H, W)``.

    Examples:
        >>> f = torch.tensor([[[[0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 3.0]]]])
        >>> local_maxima(f)[0, 0, 0].nonzero().flatten().tolist()
        [1, 6]
    """
    if f.numel() == 0:
        return torch.zeros_like(f, dtype=torch.bool)
    r = window // 2
    h, w = f.shape[-2:]
    pad = nnf.pad(f, (r, r, r, r), value=-torch.inf)  # outside cells never win
    rows = pad[..., :, :w].clone()
    for d in range(1, window):  # separable running maximum: shifted views, no pooling kernel
        torch.maximum(rows, pad[..., :, d : d + w], out=rows)
    peak = rows[..., :h, :].clone()
    for d in range(1, window):
        torch.maximum(peak, rows[..., d : d + h, :], out=peak)
    return f == peak


def seed_order(f: Tensor, seeds: Tensor) -> np.ndarray:
    """Flat indices of the seeds of one image, brightest first (ties: smaller index first).

    Args:
        f: ``(H, W)`` image the seeds were found on.
        seeds: bool ``(H, W)`` seed mask.

    Returns:
        int64 numpy array of flat (row-major) indices.

    Examples:
        >>> f = torch.tensor([[1.0, 3.0], [3.0, 2.0]])
        >>> seed_order(f, f > 1).tolist()
        [1, 2, 3]
    """
    idx = np.flatnonzero(seeds.reshape(-1).cpu().numpy())
    vals = f.reshape(-1).cpu().numpy()[idx]
    return idx[np.argsort(-vals, kind="stable")]
