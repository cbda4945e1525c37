"""Per-target image strips: the rows around each target, full width (azimuth is periodic)."""

from __future__ import annotations

import math

import torch
from torch import Tensor

__all__ = ["background", "peak_in_window", "robust_pattern", "strips"]


def strips(images: Tensor, batch: Tensor, rows: Tensor, half: int) -> Tensor:
    """Rows ``rows[t] - half .. rows[t] + half`` (circular) of image ``batch[t]``.

    Args:
        images: ``(B, C, H, W)`` (complex or real).
        batch: long ``(T,)`` scene index of each target.
        rows: long ``(T,)`` centre row of each target.
        half: half-height of a strip in rows.

    Returns:
        ``(T, C, 2 half + 1, W)``.
    """
    h = images.shape[-2]
    r = (rows.to(images.device)[:, None] + torch.arange(-half, half + 1, device=images.device)) % h
    b = batch.to(images.device)
    return images[b[:, None], :, r].transpose(1, 2)


def peak_in_window(intensity: Tensor, center: Tensor, half: int) -> tuple[Tensor, Tensor]:
    """Maximum of ``intensity (..., S, W)`` in columns ``center ± half`` (circular).

    ``center`` is a long tensor broadcastable to ``intensity.shape[:-2]``.

    Returns:
        ``(value (...), pixel (..., 2))``: the maximum and its ``(row, column)`` in the strip.
    """
    s, w = intensity.shape[-2:]
    offsets = torch.arange(-half, half + 1, device=intensity.device)
    cols = (center.to(intensity.device)[..., None] + offsets) % w  # (..., 2 half + 1)
    cols = cols.expand(*intensity.shape[:-2], cols.shape[-1])
    win = torch.gather(intensity, -1, cols[..., None, :].expand(*cols.shape[:-1], s, -1))
    value, flat = win.flatten(-2).max(-1)
    n = cols.shape[-1]
    col = torch.gather(cols, -1, (flat % n)[..., None])[..., 0]
    return value, torch.stack([flat // n, col], dim=-1)


def background(intensity: Tensor) -> Tensor:
    """Mean background intensity per image, ``median / ln 2`` (robust to the few targets)."""
    return intensity.flatten(-2).double().median(dim=-1).values / math.log(2)


def robust_pattern(values: Tensor, valid: Tensor, *, min_count: int = 3) -> Tensor:
    """Per-scene median ``(B, 1, ...)`` of ``values (B, N, ...)`` over valid targets.

    The stationary pattern: what every stationary target shows (zero by construction up to
    systematic errors); with fewer than ``min_count`` targets a median cannot outvote a
    mover, so the construction value 0 is used.
    """
    x = torch.where(valid.reshape(*valid.shape, *[1] * (values.dim() - 2)), values, torch.nan)
    med = x.nanmedian(dim=1, keepdim=True).values if x.shape[1] else x.sum(1, keepdim=True)
    enough = valid.sum(1) >= min_count
    enough = enough.reshape(enough.shape[0], *[1] * (med.dim() - 1))
    return torch.where(enough, torch.nan_to_num(med), torch.zeros_like(med))
