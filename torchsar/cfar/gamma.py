"""Gamma (L-look) distribution CFAR."""

from __future__ import annotations

from functools import partial

from torch import Tensor

from torchsar._checks import check_positive
from torchsar.cfar.distribution import distribution_cfar, distribution_threshold
from torchsar.cfar.thresholds import ca_factor, factor_map
from torchsar.detection import WINDOW, Detection, DetectorSpec
from torchsar.windows import Sums

__all__ = ["gamma"]


def gamma(
    x: Tensor,
    *,
    guard: int = 2,
    train: int = 4,
    pfa: float = 1e-3,
    looks: float = 1.0,
    valid: Tensor | None = None,
) -> Detection:
    """Gamma CFAR for L-look intensity: the fitted quantile is ``mean_ring * alpha(n, L)``.

    With ``L`` known, the only clutter parameter is the mean, estimated by the ring mean
    ``m`` (``n`` cells). ``I / m`` then follows ``F(2L, 2nL)`` exactly, so the quantile
    ``q = m * F^-1(1 - pfa; 2L, 2nL)`` (:func:`~torchsar.cfar.thresholds.ca_factor`) keeps the
    design ``pfa`` exactly on L-look gamma clutter for every ring size. The mask equals that
    of :func:`~torchsar.cfar.ca` with the same ``looks``; only the statistic's scale differs.

    Statistic ``I / q``, threshold 1 (see :mod:`torchsar.cfar.distribution`).

    Args:
        x: intensity ``(B, C, H, W)``, non-negative and finite.
        guard: guard half-width g.
        train: training-band width t.
        pfa: design probability of false alarm.
        looks: number of looks L (> 0).
        valid: optional bool mask of usable cells.

    Returns:
        :class:`Detection` with ``threshold = 1``.

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        Oliver, C., Quegan, S., Understanding Synthetic Aperture Radar Images, SciTech, 2004;
        Gandhi & Kassam, IEEE TAES 24(4), 1988, doi:10.1109/7.7181.

    Examples:
        >>> x = torch.ones(1, 1, 16, 16); x[0, 0, 8, 8] = 100.0
        >>> gamma(x, guard=1, train=2, looks=4.0).mask.sum().item()
        1
    """
    looks = check_positive(looks, "looks")
    quantile = partial(_quantile, looks=looks)
    return distribution_cfar(
        x, guard, train, pfa, valid, quantile, log_domain=False, detector="gamma"
    )


def _quantile(s: Sums, pfa: float, looks: float) -> Tensor:
    alpha = factor_map(s.count.to(s.s1.dtype), partial(ca_factor, pfa=pfa, looks=looks))
    return s.mean() * alpha


SPEC = DetectorSpec(
    name="gamma",
    detect=gamma,
    order=9,
    options={**WINDOW, "looks": 1.0},
    threshold=distribution_threshold,
)
"""The registry entry of this detector (:class:`~torchsar.detection.DetectorSpec`)."""
