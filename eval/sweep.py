"""Choose a detector's best setting on a tuning set: a grid of parameters, scored by FoM.

Window CFARs are swept over ``guard x train`` windows and design ``pfa`` values. One detector
pass per window gives the statistic; the thresholds of the other ``pfa`` values are read
from the detector itself on a small dummy image (the interior threshold; the border
rescaling of the chosen setting is exact again in the final evaluation, which reruns the
detector at the chosen ``pfa``). Scores are object-level counts from
:func:`torchsar.metrics.object_counts`; the best setting maximises FoM, then mean IoU.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from torch import Tensor

import torchsar as ts
from eval.detectors import DetectorSpec
from eval.errors import EvalError
from torchsar.metrics import ObjectCounts, object_counts

__all__ = ["Choice", "best_setting", "window_grid"]


@dataclass(frozen=True)
class Choice:
    """The chosen parameters of one detector and their tuning scores."""

    params: dict[str, Any]
    counts: ObjectCounts
    tried: int

    @property
    def key(self) -> tuple[float, float]:
        """Ranking key: FoM, then mean IoU (NaN counts as worst)."""
        return tuple(-1.0 if math.isnan(v) else v for v in (self.counts.fom, self.counts.mean_iou))


def window_grid(
    guards: Iterable[int], trains: Iterable[int], pfas: Iterable[float]
) -> list[dict[str, Any]]:
    """Every ``{"guard", "train", "pfa"}`` combination."""
    return [
        {"guard": g, "train": t, "pfa": p} for g, t, p in itertools.product(guards, trains, pfas)
    ]


def _counts(det_stat: Tensor, thr: float, batches: list[dict]) -> ObjectCounts:
    total = ObjectCounts()
    for stat, b in zip(det_stat, batches, strict=True):
        total = total + object_counts(stat > thr, b["instances"], b["ignore"])
    return total


def _threshold(spec: DetectorSpec, params: Mapping[str, Any]) -> float:
    """The detector's design threshold for ``params`` (no image needed)."""
    return ts.cfar.threshold(spec.fn, **params)


def best_setting(spec: DetectorSpec, grid: list[dict[str, Any]], batches: list[dict]) -> Choice:
    """The grid point with the best FoM on ``batches`` (dicts with ``image``,
    ``instances``, ``ignore``), one detector pass per distinct window."""
    best: Choice | None = None
    windows = {(p["guard"], p["train"]) for p in grid}
    for g, t in sorted(windows):
        sub = [p for p in grid if (p["guard"], p["train"]) == (g, t)]
        fixed = {**spec.params, **sub[0]}
        if any(2 * (g + t) + 1 > min(b["image"].shape[-2:]) for b in batches):
            continue  # the window does not fit these images
        stats = [spec.fn(b["image"], **fixed).statistic for b in batches]
        for p in sub:
            params = {**spec.params, **p}
            c = Choice(params, _counts(stats, _threshold(spec, params), batches), len(grid))
            if best is None or c.key > best.key:
                best = c
    if best is None:
        raise EvalError(f"no window of the grid fits the tuning images for {spec.name}")
    return best
