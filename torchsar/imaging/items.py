"""Batch items with nothing to focus (all-zero data)."""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["fill_items", "nonzero_items"]


def nonzero_items(x: Tensor) -> Tensor:
    """Bool ``(B,)``: item ``b`` of ``x (B, ...)`` has some non-zero value.

    An all-zero item has no energy to focus: entropy and sparsity objectives have no
    gradient there (``0 * log 0``), so autofocus methods leave it out and report phase 0.

    Examples:
        >>> x = torch.zeros(3, 2, 2, dtype=torch.complex64); x[1, 0, 0] = 1
        >>> nonzero_items(x).tolist()
        [False, True, False]
    """
    return (x.flatten(1) != 0).any(1) if x.dim() > 1 else x != 0


def fill_items(live: Tensor, values: Tensor, fill: float = 0.0) -> Tensor:
    """Values of the ``live`` items put back into a batch of ``len(live)`` (``fill`` elsewhere).

    Examples:
        >>> fill_items(torch.tensor([False, True]), torch.tensor([[5.0, 6.0]])).tolist()
        [[0.0, 0.0], [5.0, 6.0]]
    """
    out = torch.full(
        (live.numel(), *values.shape[1:]), fill, dtype=values.dtype, device=values.device
    )
    out[live.to(values.device)] = values
    return out
