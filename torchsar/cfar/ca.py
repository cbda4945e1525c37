"""Cell-averaging CFAR."""

from __future__ import annotations

from functools import partial

from torch import Tensor

from torchsar._checks import check_positive, check_probability
from torchsar.cfar.core import conclude, out_dtype, prepare
from torchsar.cfar.ring_mean import ring_mean_ratio
from torchsar.cfar.thresholds import ca_factor
from torchsar.detection import Detection
from torchsar.windows import Ring

__all__ = ["ca", "ca_threshold"]


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
    ring, pfa, vmask = prepare(x, guard, train, pfa, valid, detector="ca")
    factor = partial(ca_factor, pfa=pfa, looks=check_positive(looks, "looks"))
    stat = ring_mean_ratio(x, ring, factor, vmask, out_dtype(x))
    return conclude(stat, vmask, ca_threshold(guard=guard, train=train, pfa=pfa, looks=looks))


def ca_threshold(*, guard: int, train: int, pfa: float, looks: float) -> float:
    """The design threshold ``alpha(N)`` of :func:`ca` for these options (no image needed)."""
    n = Ring(guard, train).n
    return ca_factor(n, check_probability(pfa, "pfa"), check_positive(looks, "looks"))
