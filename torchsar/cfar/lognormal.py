"""Log-normal distribution CFAR."""

from __future__ import annotations

from functools import partial

from torch import Tensor

from torchsar.cfar.distribution import distribution_cfar, distribution_threshold, log_cumulants
from torchsar.cfar.thresholds import factor_map, student_factor
from torchsar.detection import WINDOW, Detection, DetectorSpec
from torchsar.windows import Sums

__all__ = ["lognormal"]


def lognormal(
    x: Tensor,
    *,
    guard: int = 2,
    train: int = 4,
    pfa: float = 1e-3,
    valid: Tensor | None = None,
) -> Detection:
    """Log-normal CFAR: fit ``ln I ~ N(m, s^2)`` to the ring, test ``I`` against its quantile.

    ``m`` and ``s^2`` are the ring's mean and unbiased variance of ``ln I``; the quantile is
    the exact prediction bound ``exp(m + s t_{n-1}^{-1}(1 - pfa) sqrt(1 + 1/n))`` (Student t
    with ``n - 1`` degrees of freedom), so the false-alarm rate is exactly ``pfa`` on
    homogeneous log-normal clutter for every ring size (border pixels included). This is the
    log-t detector of Goldstein (1973).

    Statistic ``I / q``, threshold 1 (see :mod:`torchsar.cfar.distribution`).

    Args:
        x: intensity ``(B, C, H, W)``, non-negative and finite (zeros are clamped to the
            smallest normal number before the logarithm).
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
        Goldstein, G. B., False-alarm regulation in log-normal and Weibull clutter, IEEE TAES
        9(1), 84-92, 1973, doi:10.1109/TAES.1973.309705.

    Examples:
        >>> x = torch.ones(1, 1, 16, 16) + 0.1 * torch.rand(1, 1, 16, 16); x[0, 0, 8, 8] = 100.0
        >>> lognormal(x, guard=1, train=2).mask[0, 0, 8, 8].item()
        True
    """
    return distribution_cfar(
        x, guard, train, pfa, valid, _quantile, log_domain=True, detector="lognormal"
    )


def _quantile(s: Sums, pfa: float) -> Tensor:
    m, v = log_cumulants(s)
    k = factor_map(s.count.to(m.dtype), partial(student_factor, pfa=pfa))
    return (m + v.sqrt() * k).exp()


SPEC = DetectorSpec(
    name="lognormal", detect=lognormal, order=7, options=WINDOW, threshold=distribution_threshold
)
"""The registry entry of this detector (:class:`~torchsar.detection.DetectorSpec`)."""
