"""Paired comparison of two detectors scored on the same images.

Every detector's bootstrap replicates weight each image (or each resampling unit, see
:attr:`~torchsar.metrics.ImageInfo.boot_key`) by the same Poisson weights, drawn from the
image's key and the seed only (:mod:`torchsar.metrics.bootstrap`). Replicate ``r`` of two
detectors is therefore the same resampled dataset, and the correlation of the two metrics
over the replicates is the paired one: what varies from image to image for both detectors
cancels out.

The interval of a difference ``a - b`` is built from each detector's own interval
(:mod:`torchsar.metrics.intervals`: effective-count, bias-corrected where the metric is, never
zero-width at 0 or 1) and that correlation ``r``, by the method of variance estimates
recovery (Zou & Donner, "Construction of confidence limits about effect measures: a general
approach", Stat. Med. 27(10), 2008, doi:10.1002/sim.3095; Newcombe's square-and-add for
paired proportions): with centres ``a, b`` and bounds ``[la, ua]``, ``[lb, ub]``::

    lo = (a - b) - sqrt((a - la)^2 + (ub - b)^2 - 2 r (a - la)(ub - b))
    hi = (a - b) + sqrt((ua - a)^2 + (b - lb)^2 - 2 r (ua - a)(b - lb))

Two detectors whose metric agrees on the sample and on every replicate (a detector against
itself, or against a strictly increasing map of its own scores) differ by exactly 0,
interval ``[0, 0]``. The interval always contains the difference of the points (a bound the
bias correction moved past it is moved to it, as for every interval).
"""

from __future__ import annotations

import math

import numpy as np

from torchsar.metrics.intervals import Interval
from torchsar.metrics.object_state import ObjectState

__all__ = ["PAIRED_METRICS", "difference_intervals", "paired_differences", "side"]

PAIRED_METRICS = ("f1", "recall", "pd_at_1_fa_per_image", "ap50")
"""The metrics compared: F1 and recall at each detector's operating point, Pd at 1 false
alarm per image, AP50."""

Side = tuple[dict, dict, dict]
"""One detector's ``(metrics, replicate_metrics, intervals)``."""


def side(state: ObjectState, threshold: float | str | None = "design", level: float = 0.95) -> Side:
    """What :func:`difference_intervals` needs of one detector at its operating point
    (``threshold``: see :meth:`ObjectState.metrics`)."""
    return (
        state.metrics(threshold),
        state.replicate_metrics(threshold),
        state.intervals(threshold, level),
    )


def paired_differences(
    a: ObjectState,
    b: ObjectState,
    at_a: float | str | None = "design",
    at_b: float | str | None = "design",
    level: float = 0.95,
) -> dict[str, tuple[float, float, float]]:
    """``metric(a) - metric(b)`` for each of :data:`PAIRED_METRICS`, with its paired
    interval (see the module docstring): ``{metric: (difference, lo, hi)}``.

    Args:
        a, b: the states of two detectors on the same images, with the same bootstrap
            replicates and seed.
        at_a, at_b: each one's operating threshold (default: its design point; ``None``:
            every detection).
        level: the interval's level.

    Returns:
        The difference of the point estimates and its interval (NaN without replicates or
        where either metric is undefined).

    Raises:
        ValueError: the states have different bootstrap settings.
    """
    if (a.replicates, a.seed) != (b.replicates, b.seed):
        raise ValueError("paired differences need the same bootstrap replicates and seed")
    return difference_intervals(side(a, at_a, level), side(b, at_b, level))


def _correlation(x: np.ndarray, y: np.ndarray) -> float:
    """Correlation over the replicates where both are defined (0 without spread)."""
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 2:
        return 0.0
    x, y = x[ok] - x[ok].mean(), y[ok] - y[ok].mean()
    den = math.sqrt(float(x @ x) * float(y @ y))
    return float(x @ y) / den if den > 0 else 0.0


def _mover(ia: Interval, ib: Interval, r: float) -> tuple[float, float]:
    a, b = ia.centre, ib.centre
    da_lo, da_hi, db_lo, db_hi = a - ia.lo, ia.hi - a, b - ib.lo, ib.hi - b
    d = a - b
    lo = d - math.sqrt(max(da_lo**2 + db_hi**2 - 2 * r * da_lo * db_hi, 0.0))
    hi = d + math.sqrt(max(da_hi**2 + db_lo**2 - 2 * r * da_hi * db_lo, 0.0))
    return lo, hi


def difference_intervals(a: Side, b: Side) -> dict[str, tuple[float, float, float]]:
    """:func:`paired_differences` from each detector's :func:`side` (computed once when one
    detector is compared with several)."""
    (ma, ra, ia), (mb, rb, ib) = a, b
    nan = float("nan")
    out = {}
    for k in PAIRED_METRICS:
        d = float(ma[k] - mb[k])
        if ma[k] == mb[k] and np.array_equal(ra[k], rb[k], equal_nan=True):
            out[k] = (0.0, 0.0, 0.0) if ra[k].size else (0.0, nan, nan)
            continue
        x, y = ia.get(k), ib.get(k)
        if x is None or y is None or not np.isfinite([x.lo, x.hi, y.lo, y.hi]).all():
            out[k] = (d, nan, nan)
            continue
        lo, hi = _mover(x, y, _correlation(ra[k], rb[k]))
        out[k] = (d, min(lo, d), max(hi, d))
    return out
