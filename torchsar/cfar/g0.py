"""G0-distribution CFAR."""

from __future__ import annotations

from functools import partial

from torch import Tensor

from torchsar._checks import check_positive
from torchsar.cfar.distribution import distribution_cfar, distribution_threshold, log_t_quantile
from torchsar.detection import WINDOW, Detection, DetectorSpec
from torchsar.windows import Sums

__all__ = ["g0"]


def g0(
    x: Tensor,
    *,
    guard: int = 2,
    train: int = 4,
    pfa: float = 1e-3,
    looks: float = 1.0,
    valid: Tensor | None = None,
) -> Detection:
    """G0-distribution CFAR (Frery et al. 1997), fitted to the ring by log-cumulants.

    Model (as in :func:`torchsar.simulate.clutter`, ``model="g0"``): ``I = X Y`` with L-look
    speckle ``Y ~ Gamma(L, 1/L)`` and inverse-gamma texture ``X = gamma / G_a`` (roughness
    ``a > 0``, i.e. ``alpha_G0 = -a``; scale ``gamma``), so ``I = gamma F(2L, 2a) / a``.
    From the ring's log-cumulants ``k1``, ``k2`` (mean and unbiased variance of ``ln I``; no
    moment of ``I`` is needed, so heavy tails with ``a <= 2`` are fine): the roughness from
    ``k2 = psi_1(L) + psi_1(a)`` (inverse trigamma, clamped to ``[0.05, 1000]``), and the
    quantile ``q = exp(k1 + t(a, n) sqrt(k2))`` with the log-t factor ``t`` calibrated for
    the G0 law of that roughness (survival ``F(2L, 2a)``) and the ring size ``n``, including
    the estimation noise of ``k1``, ``k2`` and of the shape itself
    (:mod:`torchsar.cfar.log_t`). The realised false-alarm rate on G0 clutter is close to
    ``pfa`` (measured in the tests and by ``torchsar-eval pfa``; at L = 1, a = 3 it holds at
    1e-2 and 1e-3 but runs ~3x high at 1e-4).

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
        Frery, A. C., Muller, H.-J., Yanasse, C. C. F., Sant'Anna, S. J. S., A model for
        extremely heterogeneous clutter, IEEE TGRS 35(3), 648-659, 1997,
        doi:10.1109/36.581981; Tison et al., IEEE TGRS 42(10), 2004,
        doi:10.1109/TGRS.2004.834630 (log-cumulants).

    Examples:
        >>> x = torch.ones(1, 1, 16, 16) + 0.5 * torch.rand(1, 1, 16, 16); x[0, 0, 8, 8] = 100.0
        >>> g0(x, guard=1, train=2).mask[0, 0, 8, 8].item()
        True
    """
    looks = check_positive(looks, "looks")
    return distribution_cfar(
        x, guard, train, pfa, valid, partial(_quantile, looks=looks), log_domain=True, detector="g0"
    )


def _quantile(s: Sums, pfa: float, looks: float) -> Tensor:
    return log_t_quantile(s, pfa, "g0", looks)


SPEC = DetectorSpec(
    name="g0",
    detect=g0,
    order=11,
    options={**WINDOW, "looks": 1.0},
    threshold=distribution_threshold,
)
"""The registry entry of this detector (:class:`~torchsar.detection.DetectorSpec`)."""
