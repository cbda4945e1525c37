"""Keep a subset of the targets of per-target results, in order, padded like the original."""

from __future__ import annotations

import dataclasses
from typing import TypeVar

import torch
from torch import Tensor

__all__ = ["repack"]

T = TypeVar("T")


def _pad_value(x: Tensor) -> float | bool | int:
    """What padding rows hold: NaN (floating), False (bool), -1 (integer)."""
    if x.dtype == torch.bool:
        return False
    return float("nan") if x.is_floating_point() or x.is_complex() else -1


def repack(result: T, keep: Tensor) -> T:
    """The frozen dataclass ``result`` with only the targets ``keep`` (bool ``(B, N)``).

    Every tensor field whose leading dims are ``(B, N)`` is re-packed: the kept targets of
    each scene first, in their original order, then padding (NaN / False / -1) up to the
    largest kept count; other fields are left as they are.

    Examples:
        >>> from torchsar.motion.targets import Targets
        >>> pixel = torch.tensor([[[1, 1], [2, 2], [3, 3]]])
        >>> value, zero = torch.tensor([[9.0, 5.0, 4.0]]), torch.zeros(1, 3)
        >>> t = Targets(pixel, pixel[..., 0] > 0, value, zero, zero.long())
        >>> r = repack(t, torch.tensor([[True, False, True]]))
        >>> r.pixel.tolist(), r.value.tolist()
        ([[[1, 1], [3, 3]]], [[9.0, 4.0]])
    """
    b, n = keep.shape
    m = int(keep.sum(1).max()) if b else 0
    order = torch.sort((~keep).to(torch.uint8), dim=1, stable=True).indices[:, :m]
    kept = torch.gather(keep, 1, order)
    out = {}
    for field in dataclasses.fields(result):  # type: ignore[arg-type]
        x = getattr(result, field.name)
        if isinstance(x, Tensor) and x.dim() >= 2 and tuple(x.shape[:2]) == (b, n):
            idx = order.to(x.device).reshape(b, m, *[1] * (x.dim() - 2)).expand(b, m, *x.shape[2:])
            y = torch.gather(x, 1, idx)
            mask = kept.to(x.device).reshape(b, m, *[1] * (x.dim() - 2))
            x = torch.where(mask, y, torch.full_like(y, _pad_value(y)))
        out[field.name] = x
    return type(result)(**out)
