"""What an evaluation gives back: its tables, each built from the merged states when it is
first read (:class:`LazyTables`), and :class:`Results`, the tables with the states and the
run's statistics (what :func:`~torchsar_eval.evaluate` and
:meth:`~torchsar_eval.Evaluator.compute` return)."""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from torchsar_eval.sweep import as_frame
from torchsar_eval.tables import (
    breakdown_table,
    coco_table,
    errors_table,
    froc_table,
    paired_table,
    pixel_roc_table,
    pr_table,
    scr_table,
    summary_table,
    timing_table,
)

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["BUILDERS", "LazyTables", "Results", "result_tables"]


BUILDERS = {
    "summary": summary_table,
    "froc": froc_table,
    "pr": pr_table,
    "pixel_roc": pixel_roc_table,
    "breakdown": breakdown_table,
    "timing": timing_table,
    "coco": coco_table,
    "scr": scr_table,
    "errors": errors_table,
    "paired": paired_table,
}
"""How each table of a run is built from ``{dataset: [DetectorResult]}`` (its file:
:data:`torchsar_eval.report.TABLE_FILES`)."""


def result_tables(results: dict) -> dict[str, pd.DataFrame]:
    """Every merged table of a run (``{dataset: [DetectorResult]}``), by the keys of
    :data:`BUILDERS`."""
    return {key: build(results) for key, build in BUILDERS.items()}


class LazyTables(Mapping):
    """:func:`result_tables` with each table built when it is first read (of final states:
    the run is over when it is made).

    Examples:
        >>> tables = LazyTables({})
        >>> sorted(tables) == sorted(BUILDERS), tables.built
        (True, [])
        >>> len(tables["summary"]), tables.built
        (0, ['summary'])
    """

    def __init__(self, results: dict) -> None:
        self._results = results
        self._built: dict[str, pd.DataFrame] = {}

    @property
    def built(self) -> list[str]:
        """The tables built so far."""
        return list(self._built)

    def __getitem__(self, key: str) -> pd.DataFrame:
        if key not in self._built:
            self._built[key] = BUILDERS[key](self._results)
        return self._built[key]

    def __iter__(self) -> Iterator[str]:
        return iter(BUILDERS)

    def __len__(self) -> int:
        return len(BUILDERS)


def _table(name: str, doc: str) -> property:
    return property(lambda self: self._tables[name], doc=doc)


class Results:
    """What :func:`evaluate` returns: the tables (pandas, the CSV files of a run folder),
    the merged states and the run statistics. A table is built when it is first read (a
    run that wants only ``summary`` pays for no other); a run folder holds them all.

    Attributes:
        summary: one row per dataset x detector (``summary.csv``).
        froc, pr, pixel_roc, breakdown, timing, per_image: the other tables.
        coco: ``pycocotools``' 12 stats (with ``Scoring(coco_compatible=True)``).
        scr: Pd versus signal-to-clutter ratio per SCR bin, with Wilson intervals
            (``scr.csv``).
        errors: false alarms per type, misses per size and SCR bin (``errors.csv``).
        paired: each detector against the dataset's best by F1, paired bootstrap
            intervals of the differences (``paired.csv``).
        states: ``{dataset: [DetectorResult]}`` merged states (pixel counts and ROC,
            :class:`~torchsar.metrics.ObjectState`).
        stats: per dataset: images, wall time, shards done / resumed / retried / failed.
        out: the run folder (``None`` when nothing was written).
        files: the files written into ``out``.
        sweep: every setting a sweep tried on the calibration split, with its numbers
            there and the one chosen (``sweep.csv``; empty without a sweep).
    """

    summary = _table("summary", "One row per dataset x detector (``summary.csv``).")
    froc = _table("froc", "Pd against false alarms per image (``roc.csv``).")
    pr = _table("pr", "Precision and recall at every detection score (``pr.csv``).")
    pixel_roc = _table("pixel_roc", "The pixel ROC (``roc_pixel.csv``).")
    breakdown = _table("breakdown", "Pd by size, SCR and class (``breakdown.csv``).")
    timing = _table("timing", "Run time per detector (``timing.csv``).")
    coco = _table("coco", "pycocotools' 12 stats (``coco.csv``).")
    scr = _table("scr", "Pd versus SCR bin (``scr.csv``).")
    errors = _table("errors", "False alarms per type, misses (``errors.csv``).")
    paired = _table("paired", "Paired differences against the best (``paired.csv``).")

    def __init__(
        self,
        tables: Mapping[str, pd.DataFrame],
        *,
        per_image: pd.DataFrame,
        states: dict[str, list],
        stats: dict[str, dict],
        out: Path | None = None,
        files: Iterable[str] = (),
        sweep: pd.DataFrame | None = None,
    ) -> None:
        self._tables = tables
        self.sweep = as_frame([]) if sweep is None else sweep
        self.per_image = per_image
        self.states = states
        self.stats = stats
        self.out = out
        self.files = list(files)

    def __repr__(self) -> str:
        rows = [f"{d} / {r.detector.name}" for d, rs in self.states.items() for r in rs]
        return f"Results({', '.join(rows)}; out={self.out})"

    def row(self, dataset: str, detector: str) -> pd.Series:
        """The summary row of one dataset and detector."""
        sel = self.summary[(self.summary.dataset == dataset) & (self.summary.detector == detector)]
        if sel.empty:
            raise KeyError(f"no summary row for dataset {dataset!r} and detector {detector!r}")
        return sel.iloc[0]
