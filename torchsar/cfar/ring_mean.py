"""The ring-mean ratio ``I / mean_ring`` with the border rule: the statistic of CA (and of
AC on its censored ring)."""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from torchsar.cfar.core import border_scale, finish, ratio
from torchsar.windows import Ring, Sums, windowed

__all__ = ["ring_mean_ratio"]


def ring_mean_ratio(
    x: Tensor,
    ring: Ring,
    factor: Callable[[int], float],
    vmask: Tensor | None,
    dtype: torch.dtype,
) -> Tensor:
    """``I / mean_ring`` over the counted ring cells, rescaled by ``factor(N) / factor(n)``
    where a pixel counts ``n != N`` cells (``-inf`` where ``n == 0``), cast to ``dtype``.

    Without a mask every ring holds at least one cell (the ring fits the image) and the
    counts depend on the geometry only, so the mean is formed in place and only the frame of
    pixels within ``guard + train`` of an edge is rescaled (:func:`_scale_frame`); the
    values are bit-identical to the masked rule.
    """
    h = x.shape[-2]
    row = torch.arange(h, device=x.device).view(h, 1)  # sliced with the strip: its rows

    def statistic(xs: Tensor, sums: list[Sums], rows: Tensor) -> Tensor:
        s = sums[0]
        if vmask is None:
            stat = ratio(xs, s.s1.div_(s.count).add_(s.shift))  # float64 by promotion
            r0 = int(rows[0, 0]) if rows.numel() else 0
            _scale_frame(stat, s.count, r0, h, ring, factor)
            return stat.to(dtype)
        stat = ratio(xs.to(s.s1.dtype), s.mean())
        scale = border_scale(s.count, ring.n, factor)
        return finish(stat if scale is None else stat * scale, s.count, dtype)

    return windowed(x, [ring.region], statistic, valid=vmask, moments=1, extras=(row,))


def _scale_frame(
    stat: Tensor, count: Tensor, r0: int, h: int, ring: Ring, factor: Callable[[int], float]
) -> None:
    """Multiply, in place, the strip's frame pixels (rows ``r0 + i`` or columns within
    ``guard + train`` of an edge: cut rings) by ``factor(N) / factor(n_pixel)``; interior
    pixels are untouched. ``count`` is the strip's geometric ring count ``(rr, W)``."""
    rr, w = stat.shape[-2:]
    o = ring.outer
    left, right = min(o, w), max(w - o, o)
    lo, hi = max(0, min(o, h) - r0), min(rr, max(h - o, o) - r0)  # strip rows not in the frame
    pieces = [(slice(None), slice(0, left)), (slice(None), slice(right, w))]
    pieces += [
        (slice(0, max(lo, 0)), slice(left, right)),
        (slice(max(hi, 0), rr), slice(left, right)),
    ]
    for rows, cols in pieces:
        scale = border_scale(count[rows, cols], ring.n, factor)
        if scale is not None:
            stat[..., rows, cols] *= scale
