"""``report.html``: a run's results as one self-contained page (no network, no script),
built from the run folder's files so that any run folder, old ones included, can be
reported again or compared with others (``torchsar-eval report``).

Per dataset: a card (images, targets, classes, samples, pixel spacing, matching rule,
caveats), a leaderboard ranked by a chosen metric with its 95 % interval, the FROC,
precision-recall, pixel ROC (and, when the run has ``scr.csv``, Pd vs SCR) curves, the
paired differences, error types and breakdown tables the run has, and each detector's worst
cases (``gallery/``).

Examples:
    >>> import tempfile, torchsar_eval as te
    >>> from torchsar_eval.html_report import build_report
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     _ = te.evaluate("sim-chips", ["ca"], n=2, out=f"{tmp}/run", progress=False)
    ...     page = build_report([f"{tmp}/run"])
    >>> page.startswith("<!DOCTYPE html>") and "Leaderboard" in page
    True
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from torchsar_eval.choices import REPORT_FILE
from torchsar_eval.html_report.page import (
    DEFAULT_RANK,
    LOWER_IS_BETTER,
    RANK_METRICS,
    build_page,
    check_rank_by,
)
from torchsar_eval.html_report.runfiles import RunFiles, read_run

__all__ = [
    "DEFAULT_RANK",
    "LOWER_IS_BETTER",
    "RANK_METRICS",
    "REPORT_FILE",
    "RunFiles",
    "build_report",
    "check_rank_by",
    "read_run",
    "write_report",
]


def _rank_of(runs: list[RunFiles], rank_by: str | None) -> str:
    """``rank_by``, else the ranking the (first) run recorded, else F1."""
    if rank_by is not None:
        return rank_by
    for run in runs:
        if run.record.rank_by:
            return run.record.rank_by
    return DEFAULT_RANK


def build_report(folders: Sequence[str | Path], rank_by: str | None = None) -> str:
    """The HTML report of one run folder, or of several compared in one page
    (leaderboards over every run's detectors, curves of all, each run's cards and cases).

    Args:
        folders: run folders of ``torchsar-eval run`` (or :func:`torchsar_eval.evaluate`
            with ``out=``).
        rank_by: the metric ranking the leaderboards (a ``summary.csv`` or ``timing.csv``
            column, see :data:`RANK_METRICS`); default: the one the run recorded, else F1.
    """
    runs = [read_run(f) for f in folders]
    return build_page(runs, _rank_of(runs, rank_by))


def write_report(
    folders: Sequence[str | Path] | str | Path,
    out: str | Path | None = None,
    rank_by: str | None = None,
) -> Path:
    """Write :func:`build_report` of ``folders`` to ``out`` (default: ``report.html`` in the
    one run folder), replacing it at once (temporary name, then rename); returns its path."""
    if isinstance(folders, str | Path):
        folders = [folders]
    if out is None:
        if len(folders) != 1:
            raise ValueError("several runs compared: name the output file")
        out = Path(folders[0]) / REPORT_FILE
    out = Path(out)
    text = build_report(folders, rank_by)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)
    return out
