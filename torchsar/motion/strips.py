"""Per-target image strips: the rows around each target, full width (azimuth is periodic)."""

from __future__ import annotations

import math

import torch
from torch import Tensor

__all__ = ["background", "peak_in_box", "peak_in_window", "robust_pattern", "strips"]


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


def peak_in_box(
    intensity: Tensor, center: Tensor, half: tuple[int, int], *, rows: Tensor | None = None
) -> tuple[Tensor, Tensor]:
    """Maximum of ``intensity (..., S, W)`` in rows ``center_row ± half[0]`` (clipped to the
    strip) and columns ``center_col ± half[1]`` (circular).

    ``center`` is long ``(..., 2)`` matching ``intensity.shape[:-2]``; ``rows`` optionally
    narrows the row half-width per element (long ``(...)``, at most ``half[0]``).

    Returns:
        ``(value (...), pixel (..., 2))``: the maximum and its ``(row, column)`` in the strip.

    Examples:
        >>> x = torch.zeros(2, 9, 8); x[:, 1, 7] = 5.0; x[0, 6, 0] = 3.0; x[1, 4, 7] = 2.0
        >>> value, pix = peak_in_box(x, torch.tensor([[5, 1], [5, 1]]), (2, 2))
        >>> value.tolist(), pix.tolist()
        ([3.0, 2.0], [[6, 0], [4, 7]])
    """
    s, w = intensity.shape[-2:]
    dev = intensity.device
    index = (center[..., :1].to(dev) + torch.arange(-half[0], half[0] + 1, device=dev)).clamp(
        0, s - 1
    )
    cols = (center[..., 1:].to(dev) + torch.arange(-half[1], half[1] + 1, device=dev)) % w
    lead = [
        torch.arange(n, device=dev).reshape(-1, *[1] * (index.dim() + 1 - i))
        for i, n in enumerate(intensity.shape[:-2], start=1)
    ]
    win = intensity[(*lead, index[..., :, None], cols[..., None, :])]
    if rows is not None:
        offsets = torch.arange(-half[0], half[0] + 1, device=dev).abs()
        inside = offsets <= rows.to(dev)[..., None]
        win = torch.where(inside[..., None], win, torch.full_like(win, -torch.inf))
    value, flat = win.flatten(-2).max(-1)
    n = cols.shape[-1]
    row = torch.gather(index, -1, (flat // n)[..., None])[..., 0]
    col = torch.gather(cols, -1, (flat % n)[..., None])[..., 0]
    return value, torch.stack([row, col], dim=-1)


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
