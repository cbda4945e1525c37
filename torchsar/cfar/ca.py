"""Cell-averaging CFAR."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import torch
from torch import Tensor

from torchsar._checks import check_positive
from torchsar.cfar.core import border_scale, finish, out_dtype, prepare, ratio
from torchsar.cfar.detection import Detection, detection_from
from torchsar.cfar.thresholds import ca_factor
from torchsar.windows import Ring, Sums, windowed

__all__ = ["ca"]


def ca(
    x: Tensor,
    *,
    guard: int = 2,
    train: int = 4,
    pfa: float = 1e-3,
    looks: float = 1.0,
    valid: Tensor | None = None,
) -> Detection:
    """Cell-averaging CFAR on intensity: statistic ``I / mean_ring``, threshold ``alpha``.

    ``alpha`` is exact for L-look gamma clutter (``looks=1``: exponential,
    ``alpha = N (pfa^(-1/N) - 1)``); see :func:`~torchsar.cfar.thresholds.ca_factor`.

    Args:
        x: intensity ``(B, C, H, W)``, non-negative and finite.
        guard: guard half-width g (the ``(2g+1)^2`` box around the cell under test is excluded).
        train: training-band width t; ``N = (2(g+t)+1)^2 - (2g+1)^2`` cells.
        pfa: design probability of false alarm.
        looks: number of looks L of the gamma clutter model.
        valid: optional bool mask of usable cells (no-data excluded from rings, never detected).

    Returns:
        :class:`Detection` with ``statistic = I / mean_ring`` (border pixels rescaled to the
        interior factor, see :mod:`torchsar.cfar.core`) and ``threshold = alpha(N)``.

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        Finn & Johnson, RCA Review 29, 1968; Gandhi & Kassam, IEEE TAES 24(4), 1988,
        doi:10.1109/7.7181.

    Example:
        >>> x = torch.ones(1, 1, 16, 16); x[0, 0, 8, 8] = 100.0
        >>> ca(x, guard=1, train=2, pfa=1e-3).mask.sum().item()
        1
    """
    ring, pfa, vmask = prepare(x, guard, train, pfa, valid)
    looks = check_positive(looks, "looks")
    factor = partial(ca_factor, pfa=pfa, looks=looks)
    dtype = out_dtype(x)

    if vmask is None:
        stat = _unmasked(x, ring, factor, dtype)
        return detection_from(stat, factor(ring.n))

    def statistic(xs: Tensor, sums: list[Sums]) -> Tensor:
        s = sums[0]
        stat = ratio(xs.to(s.s1.dtype), s.mean())
        scale = border_scale(s.count, ring.n, factor)
        if scale is not None:
            stat = stat * scale
        return finish(stat, s.count, None, dtype)

    stat = windowed(x, [ring.region], statistic, valid=vmask, moments=1)
    stat = stat.masked_fill(~vmask.expand_as(stat), -float("inf"))
    return detection_from(stat, factor(ring.n))


def _unmasked(x: Tensor, ring: Ring, factor: Callable[[int], float], dtype: torch.dtype) -> Tensor:
    """The statistic without a ``valid`` mask (bit-identical to the masked path's rule):
    every ring holds at least one cell (the ring fits the image), so the mean needs no
    guard and the sums are reused in place; the ring counts depend on the geometry only, so
    the border rescaling touches just the frame of pixels within ``guard + train`` of an
    edge (:func:`_scale_frame`)."""
    h = x.shape[-2]
    row = torch.arange(h, device=x.device).view(h, 1)  # sliced with the strip: its rows

    def statistic(xs: Tensor, sums: list[Sums], rows: Tensor) -> Tensor:
        s = sums[0]
        stat = ratio(xs, s.s1.div_(s.count).add_(s.shift))  # float64 by promotion
        r0 = int(rows[0, 0]) if rows.numel() else 0
        _scale_frame(stat, s.count, r0, h, ring, factor)
        return stat.to(dtype)

    return windowed(x, [ring.region], statistic, moments=1, extras=(row,))


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
