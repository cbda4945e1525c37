"""Paired comparison of two detectors scored on the same images.

Every detector's bootstrap replicates weight each image (or each resampling unit, see
:attr:`~torchsar.metrics.ImageInfo.boot_key`) by the same Poisson weights, drawn from the
image's key and the seed only (:mod:`torchsar.metrics.bootstrap`). Replicate ``r`` of two
detectors is therefore the same resampled dataset, and the replicate-wise difference of a
metric is a paired bootstrap of the difference: what varies from image to image for both
detectors cancels out, so the interval is narrower than the two separate intervals suggest.
"""

from __future__ import annotations

import numpy as np

from torchsar.metrics.bootstrap import interval
from torchsar.metrics.object_state import ObjectState

__all__ = ["PAIRED_METRICS", "difference_intervals", "paired_differences"]

PAIRED_METRICS = ("f1", "recall", "pd_at_1_fa_per_image", "ap50")
"""The metrics compared: F1 and recall at each detector's operating point, Pd at 1 false
alarm per image, AP50."""


def paired_differences(
    a: ObjectState,
    b: ObjectState,
    at_a: int | None = None,
    at_b: int | None = None,
    level: float = 0.95,
) -> dict[str, tuple[float, float, float]]:
    """``metric(a) - metric(b)`` for each of :data:`PAIRED_METRICS`, with the percentile
    interval of the replicate-wise differences: ``{metric: (difference, lo, hi)}``.

    Args:
        a, b: the states of two detectors on the same images, with the same bootstrap
            replicates and seed.
        at_a, at_b: each one's operating point (score bin; default: its design point).
        level: the interval's level.

    Returns:
        The difference of the point estimates, and the interval (NaN without replicates).
        Replicates where either metric is undefined are left out.

    Raises:
        ValueError: the states have different bootstrap settings.
    """
    if (a.replicates, a.seed) != (b.replicates, b.seed):
        raise ValueError("paired differences need the same bootstrap replicates and seed")
    return difference_intervals(
        (a.metrics(at_a), a.replicate_metrics(at_a)),
        (b.metrics(at_b), b.replicate_metrics(at_b)),
        level,
    )


def difference_intervals(
    a: tuple[dict, dict], b: tuple[dict, dict], level: float = 0.95
) -> dict[str, tuple[float, float, float]]:
    """:func:`paired_differences` from each state's ``(metrics, replicate_metrics)``
    (computed once when one detector is compared with several)."""
    (ma, ra), (mb, rb) = a, b
    out = {}
    for k in PAIRED_METRICS:
        reps = ra[k] - rb[k]
        lo, hi = interval(reps, level) if reps.size else (np.nan, np.nan)
        out[k] = (float(ma[k] - mb[k]), lo, hi)
    return out
