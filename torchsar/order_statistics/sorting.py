"""Argsort along the last axis, the one sort both order-statistic algorithms rank with."""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["argsort_rows"]


def argsort_rows(v: Tensor) -> Tensor:
    """Ascending argsort along the last axis (int64).

    On CPU numpy's sort is used (several times faster than ``torch.sort`` there); dtypes numpy
    lacks (bfloat16) are ordered through an exact float32 copy. Ties come out in a fixed
    order, so the result is deterministic.
    """
    if v.device.type != "cpu":
        return torch.sort(v, dim=-1, stable=True).indices
    if v.dtype == torch.bfloat16:
        v = v.float()
    return torch.from_numpy(v.detach().numpy().argsort(axis=-1))
