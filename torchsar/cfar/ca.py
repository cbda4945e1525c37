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
from torchsar.windows import Ring, Sums, region_count, windowed

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
    """The statistic without a ``valid`` mask: every ring holds at least one cell (the ring
    fits the image), so the mean needs no guard and the sums are reused in place; the ring
    counts depend on the geometry only, so the border rescaling touches just the frame of
    pixels within ``guard + train`` of an edge (:func:`_scale_frame`)."""

    def statistic(xs: Tensor, sums: list[Sums]) -> Tensor:
        s = sums[0]
        return ratio(xs, s.s1.div_(s.count).add_(s.shift)).to(dtype)  # float64 by promotion

    stat = windowed(x, [ring.region], statistic, moments=1)
    _scale_frame(stat, ring, factor)
    return stat


def _scale_frame(stat: Tensor, ring: Ring, factor: Callable[[int], float]) -> None:
    """Multiply the frame pixels (cut rings) by ``factor(N) / factor(n_pixel)`` in place
    (in float64, then rounded to the statistic's dtype); interior pixels are untouched."""
    h, w = stat.shape[-2:]
    o = ring.outer
    count = region_count(h, w, ring.region, stat.device)
    top, bot = min(o, h), max(h - o, o)
    left, right = min(o, w), max(w - o, o)
    frame = (
        (slice(0, top), slice(None)),
        (slice(bot, h), slice(None)),
        (slice(top, bot), slice(0, left)),
        (slice(top, bot), slice(right, w)),
    )
    for rows, cols in frame:
        scale = border_scale(count[rows, cols], ring.n, factor)
        if scale is not None:
            part = stat[..., rows, cols]
            part.copy_(part.to(torch.float64) * scale)
