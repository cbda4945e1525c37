"""Operating points chosen without peeking: a calibration split picks each detector's score
threshold (one of its detection scores), a disjoint test split reports at it.

The split is by item index: item ``i`` of a dataset belongs to the calibration split when a
hash of ``(dataset name, i)`` falls below the fraction, so it is deterministic, disjoint,
and independent of batching or sharding.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

from torchsar.metrics import ObjectState
from torchsar_eval.errors import EvalError

__all__ = ["Target", "choose_threshold", "parse_target", "split_indices"]


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


def choose_threshold(state: ObjectState, target: Target) -> float | None:
    """The operating threshold the calibration split picks, at one of its detection scores
    (detections scoring above it count; ``None``: every detection): the most detections
    with at most ``level`` false alarms per image, or the best F1 (ties: fewer detections).
    A strictly increasing map of the scores maps the chosen threshold with them."""
    return state.choose_threshold(target.kind, target.level)
