"""A dataset's leaderboard, shared by ``report.html`` and ``summary.md``: rows ranked by
one metric, a one-line note beside a detector with no detection or with the same results
as a row above it, and the dataset's caveats (display data, box ground truth, few
targets, left-out files)."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from torchsar_eval.choices import DEFAULT_RANK, RANK_METRICS
from torchsar_eval.errors import EvalError

if TYPE_CHECKING:
    from torchsar_eval.html_report.runfiles import RunFiles

__all__ = [
    "DEFAULT_RANK",
    "LOWER_IS_BETTER",
    "NO_DETECTION",
    "RANK_METRICS",
    "Board",
    "caveats",
    "check_rank_by",
    "number",
    "short_value",
]

LOWER_IS_BETTER = {
    "false_alarms_per_image",
    "false_alarms",
    "fp",
    "fn",
    "pfa_pixel",
    "fa_per_km2",
    "fragmentation",
    "ms_per_image",
    "object_ms_per_image",
}
NO_DETECTION = "no detection above its threshold on this data"
FEW_TARGETS = 30
"""Below this many targets a dataset's card says that its intervals are wide."""
_NOT_COMPARED = {"dataset", "detector", "score_threshold", "run"}


def check_rank_by(metric: str, columns: Iterable[str] = ()) -> str:
    """``metric`` if a leaderboard can be ranked by it (:data:`RANK_METRICS`, or a numeric
    column ``columns`` of the run's summary); :class:`EvalError` otherwise."""
    if metric in RANK_METRICS or metric in set(columns) - _NOT_COMPARED - {"images", "targets"}:
        return metric
    raise EvalError(
        f"{{opt:rank_by}}{metric!r}: not a metric; choose one of {', '.join(RANK_METRICS)}"
    )


def number(v: object) -> float:
    """``float(v)``, NaN for what is not a number."""
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


class Board:
    """One dataset's leaderboard over one or more runs: ``rows`` (one per run x detector,
    best first by ``rank_by``; ties share a rank, NaN last without one), ``rank`` and
    ``notes`` (why a row is what it is, ``""`` when nothing needs saying)."""

    def __init__(self, runs: list[RunFiles], dataset: str, rank_by: str) -> None:
        self.runs, self.dataset, self.rank_by = runs, dataset, rank_by
        frames = []
        for k, run in enumerate(runs):
            s = run.table("summary", dataset).copy()
            if s.empty:
                continue
            t = run.table("timing", dataset)
            extra = [c for c in ("ms_per_image", "images_per_s") if c in t.columns]
            if extra and "detector" in t.columns:
                s = s.merge(
                    t[["detector", *extra]].drop_duplicates("detector"),
                    on="detector",
                    how="left",
                    suffixes=("", "_timing"),
                )
            s["run"], s["_run"] = run.name, k
            frames.append(s)
        self.rows = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
        many = len(runs) > 1
        pairs = zip(self.rows["detector"], self.rows["run"], strict=True)
        self.rows["label"] = [f"{d} ({r})" if many else d for d, r in pairs]
        self._rank()
        self.notes = self._notes()
        self.settings = self._settings()

    def _rank(self) -> None:
        m = self.rank_by
        values = (
            pd.to_numeric(self.rows[m], errors="coerce")
            if m in self.rows.columns
            else pd.Series(np.nan, index=self.rows.index)
        )
        sign = 1.0 if m in LOWER_IS_BETTER else -1.0
        key = (sign * values).fillna(np.inf)
        order = np.argsort(key.to_numpy(), kind="stable")
        self.rows = self.rows.iloc[order].reset_index(drop=True)
        k = key.to_numpy()[order]
        self.rank = [1 + int(np.sum(k < v)) if np.isfinite(v) else None for v in k]

    def options(self, run: int, detector: str) -> dict:
        """A row's detector options as its run applied them: the options ``config.json``
        records, the settings a sweep chose over them, the operating threshold."""
        return self.runs[run].record.detector_options(self.dataset, detector)

    def _settings(self) -> list[str]:
        """Per row, the options in which its detector differs from the same detector in
        the other runs (``pfa=1e-06, train=16``; ``""`` with one run or none differing)."""
        if len(self.runs) < 2 or self.rows.empty:
            return [""] * len(self.rows)
        rows = list(zip(self.rows["_run"].astype(int), self.rows["detector"], strict=True))
        opts = [self.options(k, d) for k, d in rows]
        out = []
        for (_, d), mine in zip(rows, opts, strict=True):
            others = [o for (_, d2), o in zip(rows, opts, strict=True) if d2 == d]
            keys = sorted({k for o in others for k in o}, key=str)
            differ = [
                k
                for k in keys
                if len({json.dumps(o.get(k), default=str, sort_keys=True) for o in others}) > 1
            ]
            out.append(", ".join(f"{k}={short_value(mine.get(k))}" for k in differ))
        return out

    def _curve(self, run: int, detector: str) -> tuple:
        froc = self.runs[run].table("froc", self.dataset)
        cols = [c for c in ("tp", "fp") if c in froc.columns]
        if "detector" not in froc.columns or not cols:
            return ()
        return tuple(map(tuple, froc.loc[froc["detector"] == detector, cols].to_numpy().tolist()))

    def _notes(self) -> list[str]:
        """Why a row is what it is: no detection at all, or the same results as a row
        ranked above it."""
        cols = [
            c
            for c in self.rows.columns
            if c not in _NOT_COMPARED
            and not c.startswith("_")
            and c not in ("label", "ms_per_image", "images_per_s", "object_ms_per_image")
        ]
        seen: dict[tuple, str] = {}
        notes = []
        for _, r in self.rows.iterrows():
            if number(r.get("tp")) == 0 and number(r.get("fp")) == 0:
                notes.append(NO_DETECTION)
                continue
            key = tuple(
                None if isinstance(v, float) and math.isnan(v) else v for v in (r[c] for c in cols)
            )
            key += self._curve(int(r["_run"]), r["detector"])
            if key in seen:
                notes.append(f"identical results to {seen[key]}")
            else:
                seen[key] = r["label"]
                notes.append("")
        return notes


def short_value(v: object) -> str:
    """An option value as a row shows it (``1e-06``, ``16``, a path's last part).

    Examples:
        >>> [short_value(v) for v in (1e-6, 16, "/data/runs/preds.json", None)]
        ['1e-06', '16', 'preds.json', '–']
    """
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:g}"
    text = str(v)
    return text.rsplit("/", 1)[-1] if "/" in text else text


def caveats(run: RunFiles, dataset: str, board: Board) -> list[str]:
    """What a reader must know before comparing ``dataset``'s numbers, one line each."""
    ds = run.record.dataset(dataset)
    summary = run.table("summary", dataset)
    first = summary.iloc[0] if not summary.empty else pd.Series(dtype=object)
    out = []
    if ds.sample_type == "display":
        out.append(
            "display data (8/16-bit renderings of unknown transfer): the detectors' "
            "design Pfa is not meaningful on it"
        )
    if ds.gt == "box":
        out.append("box ground truth: no pixel metrics, AP at box IoU")
    n_targets = number(first.get("targets"))
    if not math.isnan(n_targets) and n_targets < FEW_TARGETS:
        out.append(f"only {n_targets:.0f} targets: intervals are wide")
    if run.record.calibration is not None:
        out.append("the worst cases in the gallery are at the design operating point")
    failed, skipped = ds.failed, ds.skipped_items
    if failed or skipped:
        out.append(f"{len(failed)} failed shard(s) and {len(skipped)} unreadable file(s) left out")
    if any(n.startswith("identical") for n in board.notes):
        out.append("some detectors give identical results (see the notes)")
    return out
