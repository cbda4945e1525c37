"""Choose a detector's best setting on a tuning set: a grid of parameters, scored by FoM.

Window CFARs are swept over ``guard x train`` windows and design ``pfa`` values. One detector
pass per window gives the statistic; the thresholds of the other ``pfa`` values come from
the detector's own threshold function (the interior threshold; the border rescaling of the
chosen setting is exact again in the final evaluation, which reruns the detector at the
chosen ``pfa``). Scores are the run's object scoring (the shared discrimination stage and
one-to-one matching, :class:`torchsar_eval.result.Scoring`); the best setting maximises FoM, then
mean IoU.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from torch import Tensor

import torchsar as ts
from torchsar.metrics import ObjectState, match_batch
from torchsar.objects import discriminate
from torchsar_eval.detector import Detector
from torchsar_eval.errors import EvalError
from torchsar_eval.result import Scoring
from torchsar_eval.scoring import batch_truth

__all__ = ["Choice", "best_setting", "window_grid"]


@dataclass(frozen=True)
class Choice:
    """The chosen parameters of one detector and their tuning scores."""

    params: dict[str, Any]
    scores: dict[str, float]
    tried: int

    @property
    def key(self) -> tuple[float, float]:
        """Ranking key: FoM, then mean IoU (NaN counts as worst)."""
        return tuple(
            -1.0 if math.isnan(v) else v for v in (self.scores["fom"], self.scores["mean_iou"])
        )


def window_grid(
    guards: Iterable[int], trains: Iterable[int], pfas: Iterable[float]
) -> list[dict[str, Any]]:
    """Every ``{"guard", "train", "pfa"}`` combination."""
    return [
        {"guard": g, "train": t, "pfa": p} for g, t, p in itertools.product(guards, trains, pfas)
    ]


def _scores(stats: list[Tensor], thr: float, batches: list[dict], scoring: Scoring) -> dict:
    """Object metrics of the statistics thresholded at ``thr`` under the run's scoring."""
    state = ObjectState(replicates=0)
    for stat, b in zip(stats, batches, strict=True):
        obj = discriminate(stat, thr, rules=scoring.rules)
        gt, info = batch_truth(b, "tuning")
        state.update(match_batch(obj, gt, scoring.matching), obj, gt, info)
    return state.metrics()


def _threshold(spec: Detector, params: Mapping[str, Any]) -> float:
    """The detector's design threshold for ``params`` (no image needed)."""
    return ts.cfar.threshold(spec.fn, **params)


def best_setting(
    spec: Detector,
    grid: list[dict[str, Any]],
    batches: list[dict],
    scoring: Scoring | None = None,
) -> Choice:
    """The grid point with the best FoM on ``batches`` (stacked dataset batches), one
    detector pass per distinct window."""
    scoring = Scoring() if scoring is None else scoring
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
            scores = _scores(stats, _threshold(spec, params), batches, scoring)
            c = Choice(params, scores, len(grid))
            if best is None or c.key > best.key:
                best = c
    if best is None:
        raise EvalError(f"no window of the grid fits the tuning images for {spec.name}")
    return best
