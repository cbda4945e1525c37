"""A run folder read back from its files (CSV tables, ``config.json``, figures, the
gallery), tolerant of what older or newer runs lack: a missing table is empty, a missing
column is skipped by whoever needs it."""

from __future__ import annotations

import json
import os
import stat
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from torchsar_eval.errors import EvalError
from torchsar_eval.html_report.records import RunRecord, run_record

__all__ = ["MAX_PNG_BYTES", "RUN_TABLES", "RunFiles", "read_png", "read_run"]

MAX_PNG_BYTES = 32 << 20
"""The largest figure a report embeds."""
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
_PNG = b"\x89PNG\r\n\x1a\n"

RUN_TABLES = {
    "summary": "summary.csv",
    "froc": "roc.csv",
    "pr": "pr.csv",
    "pixel_roc": "roc_pixel.csv",
    "breakdown": "breakdown.csv",
    "timing": "timing.csv",
    "coco": "coco.csv",
    "scr": "scr.csv",
    "errors": "errors.csv",
    "paired": "paired.csv",
    "cases": "gallery/cases.csv",
    "overlays": "overlays/overlays.csv",
    "sweep": "sweep.csv",
}
"""The files a report reads (all optional but ``summary.csv``)."""
REDRAWN = ("roc_",)
"""Figures of a run folder the report draws afresh (so it does not show them twice)."""


@dataclass
class RunFiles:
    """What a report needs of one run folder.

    Attributes:
        folder: the run folder.
        name: the run's name (its ``--out`` folder name as recorded, else the folder's).
        config: ``config.json`` (``{}`` when missing or unreadable).
        record: ``config.json`` as typed records (what pages read of it).
        tables: the tables of :data:`RUN_TABLES` (empty DataFrames when missing).
        figures: the folder's other PNG figures (those the report does not redraw).
    """

    folder: Path
    name: str
    config: dict = field(default_factory=dict)
    tables: dict[str, pd.DataFrame] = field(default_factory=dict)
    figures: list[Path] = field(default_factory=list)
    record: RunRecord = field(default_factory=RunRecord)

    def table(self, key: str, dataset: str | None = None) -> pd.DataFrame:
        """Table ``key``, only the rows of ``dataset`` when given (and it has the column)."""
        df = self.tables.get(key, pd.DataFrame())
        if dataset is not None and "dataset" in df.columns:
            df = df[df["dataset"].astype(str) == dataset]
        return df

    @property
    def datasets(self) -> list[str]:
        """The datasets of the run, in summary order."""
        return list(dict.fromkeys(self.tables["summary"]["dataset"].astype(str)))


def read_png(folder: Path, name: str) -> bytes | None:
    """The bytes of PNG ``name`` of run folder ``folder``, or ``None`` when it is not a
    figure of the run: an absolute path, a ``..`` part, a symbolic link anywhere on the
    way, not a regular file (a FIFO, a device), larger than :data:`MAX_PNG_BYTES`, or no
    PNG signature. A run's tables name files, so a report reads only what lies inside the
    run folder (nothing else of the machine can end up in ``report.html``)."""
    parts = Path(name).parts
    if not parts or Path(name).is_absolute() or ".." in parts or not _inside(folder, name):
        return None
    path = folder / name
    try:
        if os.lstat(path).st_size > MAX_PNG_BYTES:
            return None
    except (OSError, ValueError):
        return None
    try:
        fd = os.open(path, os.O_RDONLY | _NOFOLLOW)
    except OSError:
        return None
    with os.fdopen(fd, "rb") as f:
        data = f.read(MAX_PNG_BYTES + 1)
    return data if data.startswith(_PNG) and len(data) <= MAX_PNG_BYTES else None


def _inside(folder: Path, name: str) -> bool:
    """Whether ``folder/name`` is a regular file inside the run folder (no link on the
    way, no FIFO or device)."""
    path = folder
    try:
        for part in Path(name).parts:
            path = path / part
            st = os.lstat(path)
            if stat.S_ISLNK(st.st_mode):
                return False
    except (OSError, ValueError):
        return False
    return stat.S_ISREG(st.st_mode)


def _read_csv(path: Path) -> pd.DataFrame:
    if not _inside(path.parent, path.name):
        return pd.DataFrame()
    try:  # only empty cells are missing: "n/a" is a bin name (SCR not measurable)
        return pd.read_csv(path, keep_default_na=False, na_values=[""])
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, OSError) as exc:
        warnings.warn(
            f"{path}: unreadable table, left out of the report ({exc})", UserWarning, stacklevel=3
        )
        return pd.DataFrame()


def read_run(folder: str | Path) -> RunFiles:
    """Read run folder ``folder`` (a ``torchsar-eval run`` output): its tables,
    ``config.json`` and figures. :class:`EvalError` when it has no readable
    ``summary.csv`` with ``dataset`` and ``detector`` columns."""
    folder = Path(folder)
    if not folder.is_dir():
        raise EvalError(f"{folder} is not a folder: give a run folder (torchsar-eval run --out)")
    tables = {
        k: _read_csv(folder / f) if _inside(folder, f) else pd.DataFrame()
        for k, f in RUN_TABLES.items()
    }  # (only the run's own files: no link out)
    summary = tables["summary"]
    if summary.empty or not {"dataset", "detector"} <= set(summary.columns):
        raise EvalError(
            f"{folder} is not a run folder of torchsar-eval run: it has no "
            "summary.csv with dataset and detector columns"
        )
    for df in tables.values():
        for col in ("dataset", "detector"):
            if col in df.columns:
                df[col] = df[col].astype(str)
    config: dict = {}
    if _inside(folder, "config.json"):
        try:
            config = json.loads((folder / "config.json").read_text())
        except (ValueError, OSError):
            config = {}
        if not isinstance(config, dict):
            config = {}
    record = run_record(config)
    name = Path(record.out).name if record.out else folder.resolve().name
    figures = sorted(
        p for p in folder.glob("*.png") if not p.name.startswith(REDRAWN) and not p.is_symlink()
    )
    return RunFiles(folder, name, config, tables, figures, record)
