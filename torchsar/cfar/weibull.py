"""Weibull distribution CFAR."""

from __future__ import annotations

from torch import Tensor

from torchsar.cfar.distribution import distribution_cfar, distribution_threshold, log_t_quantile
from torchsar.detection import WINDOW, Detection, DetectorSpec
from torchsar.windows import Sums

__all__ = ["weibull"]


def weibull(
    x: Tensor,
    *,
    guard: int = 2,
    train: int = 4,
    pfa: float = 1e-3,
    valid: Tensor | None = None,
) -> Detection:
    """Weibull CFAR: fit ``P(I > u) = exp(-(u / lam)^c)`` to the ring by log-cumulants.

    ``ln I`` is Gumbel: ``Var ln I = pi^2 / (6 c^2)`` and ``E ln I = ln lam - gamma_E / c``,
    so ``c = pi / sqrt(6 k2)``, ``ln lam = k1 + gamma_E / c`` (method of log-cumulants); the
    quantile is ``lam (ln(1/pfa))^(1/c)``, i.e. ``ln q = k1 + sqrt(k2) sqrt(6)/pi
    (gamma_E + ln ln(1/pfa))``. The fitted parameters are plug-in estimates, so the realised
    false-alarm rate on Weibull clutter is close to (not exactly) ``pfa``; it is measured in
    the tests and in ``torchsar-eval pfa``.

    Statistic ``I / q``, threshold 1 (see :mod:`torchsar.cfar.distribution`).

    Args:
        x: intensity ``(B, C, H, W)``, non-negative and finite.
        guard: guard half-width g.
        train: training-band width t.
        pfa: design probability of false alarm.
        valid: optional bool mask of usable cells.

    Returns:
        :class:`Detection` with ``threshold = 1``.

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        Tison, C., Nicolas, J.-M., Tupin, F., Maitre, H., A new statistical model for
        Markovian classification of urban areas in high-resolution SAR images, IEEE TGRS
        42(10), 2046-2057, 2004, doi:10.1109/TGRS.2004.834630 (method of log-cumulants);
        Goldstein, IEEE TAES 9(1), 1973, doi:10.1109/TAES.1973.309705.

    Examples:
        >>> x = torch.ones(1, 1, 16, 16) + 0.1 * torch.rand(1, 1, 16, 16); x[0, 0, 8, 8] = 100.0
        >>> weibull(x, guard=1, train=2).mask[0, 0, 8, 8].item()
        True
    """
    return distribution_cfar(
        x, guard, train, pfa, valid, _quantile, log_domain=True, detector="weibull"
    )


def _quantile(s: Sums, pfa: float) -> Tensor:
    return log_t_quantile(s, pfa, "weibull", 1.0)


SPEC = DetectorSpec(
    name="weibull", detect=weibull, order=8, options=WINDOW, threshold=distribution_threshold
)
"""The registry entry of this detector (:class:`~torchsar.detection.DetectorSpec`)."""
