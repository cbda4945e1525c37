"""Operating points chosen without peeking: a calibration split picks each detector's score
threshold, a disjoint test split reports at it.

The split is by item index: item ``i`` of a dataset belongs to the calibration split when a
hash of ``(dataset name, i)`` falls below the fraction, so it is deterministic, disjoint,
and independent of batching or sharding.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from torchsar.metrics import ObjectState
from torchsar.metrics.curves import SCORE_GRID, suffix
from torchsar.metrics.object_state import operating_point
from torchsar_eval.errors import EvalError

__all__ = ["Target", "choose_bin", "parse_target", "split_indices", "threshold_of"]


@dataclass(frozen=True)
class Target:
    """What the calibration split optimises: ``kind="fa"`` (at most ``level`` false alarms
    per image, the most detections that allows) or ``kind="f1"`` (best F1)."""

    kind: str
    level: float | None = None


def parse_target(text: str) -> Target:
    """``"fa=1"`` (at most 1 false alarm per image) or ``"f1"`` (best F1)."""
    if text == "f1":
        return Target("f1")
    key, _, value = text.partition("=")
    try:
        level = float(value)
    except ValueError:
        level = float("nan")
    if key != "fa" or not level >= 0:
        raise EvalError(
            f"{{opt:calibrate_on}}{text!r}: the calibration target must be 'f1' or 'fa=LEVEL' "
            "(LEVEL >= 0)"
        )
    return Target("fa", level)


def split_indices(n: int, name: str, fraction: float) -> tuple[list[int], list[int]]:
    """``(calibration, test)`` item indices of a dataset of ``n`` items."""
    if not 0 < fraction < 1:
        raise EvalError(f"{{opt:calibration_fraction}}{fraction}: must be in (0, 1)")
    cal, test = [], []
    for i in range(n):
        h = hashlib.blake2b(f"{name}\0{i}".encode(), digest_size=8).digest()
        (cal if int.from_bytes(h, "little") / 2**64 < fraction else test).append(i)
    return cal, test


def choose_bin(state: ObjectState, target: Target) -> int:
    """The score bin where the operating point starts: the lowest score level with at most
    ``level`` false alarms per image, or the level of best F1 (ties: the higher level)."""
    n = SCORE_GRID.size + 1
    cf = suffix(state.fp)
    if target.kind == "fa":
        ok = np.flatnonzero(cf / max(state.images, 1) <= target.level)
        return int(ok[0]) if ok.size else n
    f1 = [operating_point(state.tp, state.fp, state.n_gt, state.images, j)["f1"] for j in range(n)]
    f1 = np.nan_to_num(np.array(f1), nan=-1.0)
    return int(np.flatnonzero(f1 == f1.max())[-1])


def threshold_of(bin_: int) -> float:
    """The score threshold of an operating point starting at ``bin_`` (scores above it)."""
    return float(SCORE_GRID[bin_ - 1]) if bin_ > 0 else float("-inf")
