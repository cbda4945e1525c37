"""Fair baselines: each detector's settings chosen on a calibration split, reported on the
disjoint test split.

A sweep is a grid of option values (``{"pfa": [1e-3, 1e-4], "train": [4, 8, 12]}``). Each
detector is tried at every combination of the swept options it has (a detector with none of
them keeps its own settings), all on the calibration split in one pass over its images, and
keeps the setting that best meets the calibration target at its design operating point:

- ``"f1"``: the highest F1 (ties: fewer false alarms per image, then the earlier setting);
- ``"fa=L"``: the highest Pd among the settings with at most ``L`` false alarms per image
  (ties as above); when none stays within ``L``, the setting with the fewest false alarms
  per image (the sweep table says so).

The test split is never scored before the choice is made, so nothing about it can reach the
choice. :func:`sweep_table` lists every setting tried with its calibration numbers
(``sweep.csv``); the chosen settings go into ``config.json``.
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from torchsar_eval.calibrate import Target
from torchsar_eval.detector import HARNESS_OPTIONS, Detector
from torchsar_eval.errors import EvalError

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "SWEEP_COLUMNS",
    "Setting",
    "as_frame",
    "check_sweep",
    "choose",
    "sweep_table",
    "variants",
]

SWEEP_COLUMNS = [
    "dataset",
    "detector",
    "setting",
    "options",
    "f1",
    "recall",
    "false_alarms_per_image",
    "within_target",
    "chosen",
]
"""Columns of ``sweep.csv``."""
MAX_SETTINGS = 512
"""Most settings one detector may be tried at (the grid is a product: it grows fast)."""


@dataclass(frozen=True)
class Setting:
    """One point of a detector's grid: its options and its calibration numbers."""

    detector: str
    index: int
    options: dict[str, Any]
    f1: float = math.nan
    recall: float = math.nan
    fa_per_image: float = math.nan


def check_sweep(sweep: Mapping[str, Sequence]) -> dict[str, list]:
    """The sweep as ``{option: [values]}``, each a non-empty list without repeats.

    Examples:
        >>> check_sweep({"pfa": [1e-3, 1e-4], "train": (4, 8)})
        {'pfa': [0.001, 0.0001], 'train': [4, 8]}
    """
    if not isinstance(sweep, Mapping) or not sweep:
        raise EvalError(
            "{opt:sweep} must map option names to lists of values, e.g. {'pfa': [1e-3, 1e-4]}"
        )
    out = {}
    for key, values in sweep.items():
        values = (
            list(values)
            if isinstance(values, Sequence) and not isinstance(values, str)
            else [values]
        )
        if not isinstance(key, str) or not key or not values:
            raise EvalError(f"{{opt:sweep}} option {key!r} needs at least one value")
        if len({json.dumps(v, sort_keys=True, default=str) for v in values}) != len(values):
            raise EvalError(f"{{opt:sweep}} option {key!r} repeats a value: {values}")
        out[key] = values
    return out


def variants(det: Detector, sweep: Mapping[str, list]) -> list[Detector]:
    """``det`` at every combination of the swept options it has (named ``NAME@k``), or
    ``[]`` when it has none of them."""
    keys = [k for k in sweep if det.has_option(k)]
    if not keys:
        return []
    grid = list(itertools.product(*(sweep[k] for k in keys)))
    if len(grid) > MAX_SETTINGS:
        raise EvalError(
            f"{{opt:sweep}} tries detector {det.name} at {len(grid)} settings, more "
            f"than {MAX_SETTINGS}: sweep fewer values"
        )
    out = []
    for k, values in enumerate(grid):
        point = dict(zip(keys, values, strict=True))
        harness = {o: point.pop(o) for o in HARNESS_OPTIONS if o in point}
        tried = det.with_options(point) if point else det
        out.append(replace(tried, name=f"{det.name}@{k}", **harness))
    return out


def _point(det: Detector, keys: list[str]) -> dict[str, Any]:
    """The swept options of variant ``det``."""
    got = {
        **det.options,
        "threshold": det.threshold,
        "instances": det.instances,
        "scale": det.scale,
    }
    return {k: got.get(k) for k in keys}


def choose(
    tried: list[Detector], results: list, target: Target, keys: list[str]
) -> tuple[int, list[Setting]]:
    """The index of the variant that best meets ``target`` on the calibration split
    (``results``: the variants' results there, in order; ``keys``: the swept options), and
    every setting tried."""
    settings = []
    for k, (det, r) in enumerate(zip(tried, results, strict=True)):
        m = r.objects.metrics("design")
        name = det.name.rpartition("@")[0] or det.name
        settings.append(
            Setting(
                name,
                k,
                _point(det, keys),
                float(m["f1"]),
                float(m["recall"]),
                float(m["fa_per_image"]),
            )
        )
    return min(range(len(settings)), key=lambda k: _rank(settings[k], target)), settings


def _rank(s: Setting, target: Target) -> tuple:
    """Smaller is better: the target's value, then fewer false alarms, then grid order."""
    fa = s.fa_per_image if math.isfinite(s.fa_per_image) else math.inf
    if target.kind == "f1":
        f1 = s.f1 if math.isfinite(s.f1) else -1.0
        return (-f1, fa, s.index)
    within = fa <= target.level
    recall = s.recall if math.isfinite(s.recall) else -1.0
    return (0, -recall, fa, s.index) if within else (1, fa, -recall, s.index)


def sweep_table(dataset: str, settings: list[Setting], chosen: int, target: Target) -> list[list]:
    """``sweep.csv`` rows of one detector's settings (``chosen``: the chosen index)."""
    rows = []
    for s in settings:
        within = True if target.kind == "f1" else s.fa_per_image <= target.level
        rows.append(
            [
                dataset,
                s.detector,
                s.index,
                json.dumps(s.options, default=str),
                s.f1,
                s.recall,
                s.fa_per_image,
                within,
                s.index == chosen,
            ]
        )
    return rows


def as_frame(rows: list[list]) -> pd.DataFrame:
    """``sweep.csv`` as a table."""
    import pandas as pd  # the table only: the workers import this module (settings) without pandas

    return pd.DataFrame(rows, columns=SWEEP_COLUMNS)
