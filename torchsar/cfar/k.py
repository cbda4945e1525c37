"""K-distribution CFAR."""

from __future__ import annotations

from functools import partial

from torch import Tensor

from torchsar._checks import check_positive
from torchsar.cfar.distribution import distribution_cfar, distribution_threshold, log_t_quantile
from torchsar.detection import WINDOW, Detection, DetectorSpec
from torchsar.windows import Sums

__all__ = ["k"]


def k(
    x: Tensor,
    *,
    guard: int = 2,
    train: int = 4,
    pfa: float = 1e-3,
    looks: float = 1.0,
    valid: Tensor | None = None,
) -> Detection:
    """K-distribution CFAR: texture x speckle, fitted to the ring by log-cumulants.

    Model (as in :func:`torchsar.simulate.clutter`, ``model="k"``): ``I = X Y`` with
    L-look speckle ``Y ~ Gamma(L, 1/L)`` and texture ``X ~ Gamma(nu, mu/nu)`` (mean ``mu``).
    From the ring's log-cumulants ``k1``, ``k2`` (mean and unbiased variance of ``ln I``):
    the shape from ``k2 = psi_1(L) + psi_1(nu)`` (inverse trigamma, clamped to
    ``[0.05, 1000]``; a ring less spread than pure speckle gets ``nu = 1000``, the gamma
    limit), and the quantile ``q = exp(k1 + t(nu, n) sqrt(k2))`` with the log-t factor ``t``
    calibrated for the K law of that shape and the ring size ``n``, including the
    estimation noise of ``k1``, ``k2`` and of the shape itself (:mod:`torchsar.cfar.log_t`;
    the K survival function by quadrature over the texture, cached per ``(L, pfa, n)``). The
    realised false-alarm rate on K clutter is close to ``pfa`` (measured in the tests and by
    ``torchsar-eval pfa``).

    Statistic ``I / q``, threshold 1 (see :mod:`torchsar.cfar.distribution`).

    Args:
        x: intensity ``(B, C, H, W)``, non-negative and finite.
        guard: guard half-width g.
        train: training-band width t.
        pfa: design probability of false alarm.
        looks: number of looks L of the speckle (> 0).
        valid: optional bool mask of usable cells.

    Returns:
        :class:`Detection` with ``threshold = 1``.

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        Jakeman, E., Pusey, P. N., IEEE TAP 24(6), 806-814, 1976,
        doi:10.1109/TAP.1976.1141451 (K law); Tison et al., IEEE TGRS 42(10), 2004,
        doi:10.1109/TGRS.2004.834630 (log-cumulants).

    Examples:
        >>> x = torch.ones(1, 1, 16, 16) + 0.5 * torch.rand(1, 1, 16, 16); x[0, 0, 8, 8] = 100.0
        >>> k(x, guard=1, train=2).mask[0, 0, 8, 8].item()
        True
    """
    looks = check_positive(looks, "looks")
    return distribution_cfar(
        x, guard, train, pfa, valid, partial(_quantile, looks=looks), log_domain=True, detector="k"
    )


def _quantile(s: Sums, pfa: float, looks: float) -> Tensor:
    return log_t_quantile(s, pfa, "k", looks)


SPEC = DetectorSpec(
    name="k", detect=k, order=10, options={**WINDOW, "looks": 1.0}, threshold=distribution_threshold
)
"""The registry entry of this detector (:class:`~torchsar.detection.DetectorSpec`)."""
