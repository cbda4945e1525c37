"""What a shard leaves on disk and how a folder's saved shards are merged.

A shard's state (:class:`ShardState`: every detector's mergeable results, and its COCO
export when asked for) is saved as data only (:mod:`torchsar_eval.statefile`, which may
rebuild only the classes registered here). Saved shards are merged in shard order, so any
split, worker count or resume gives identical tables; :class:`ShardMerger` merges them
while a run is still scoring.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from torchsar_eval import statefile
from torchsar_eval.coco import CocoExport
from torchsar_eval.result import DetectorResult

__all__ = [
    "ROWS_FILE",
    "ShardMerger",
    "ShardState",
    "load_shard",
    "merge",
    "shard_coco",
    "shard_files",
    "shard_path",
    "shard_rows",
]


@dataclass
class ShardState:
    """What one shard leaves on disk: every detector's mergeable results and, with
    ``export_coco``, the shard's COCO ground truth and detections."""

    results: list[DetectorResult]
    coco: CocoExport | None = None


statefile.register(ShardState)  # the other state classes: torchsar_eval.result
statefile.register(CocoExport)


def load_shard(path: Path) -> ShardState:
    """A saved shard state: data only, its content hash checked (``CorruptStateError``)."""
    with open(path, "rb") as f:
        state = statefile.loads(f.read(), f"shard state {path}")
    if not isinstance(state, ShardState):
        raise statefile.CorruptStateError(f"shard state {path} does not hold a shard")
    return state


ROWS_FILE = "rows.jsonl"
"""The per-image rows of a folder's shards, in shard order, written while they are merged."""


def merge(
    parts: Iterable[list[DetectorResult]], rows_to: IO[str] | None = None
) -> list[DetectorResult]:
    """Add shard results detector by detector, in shard order (one shard in memory at a
    time; the per-image rows are dropped, after being written to ``rows_to`` as JSON lines
    ``[detector, rows]`` when given: :func:`shard_rows` streams them from there)."""
    out = None
    for part in parts:
        out = _add(out, part, rows_to)
    return out or []


def _add(
    out: list[DetectorResult] | None, part: list[DetectorResult], rows_to: IO[str] | None
) -> list[DetectorResult]:
    """``out + part`` detector by detector, ``part``'s rows written to ``rows_to`` and
    dropped."""
    for r in part:
        if rows_to is not None:
            rows_to.write(json.dumps([r.detector.name, list(r.rows)]) + "\n")
        r.rows = []
    return part if out is None else [a + b for a, b in zip(out, part, strict=True)]


def shard_path(folder: Path, k: int) -> Path:
    """Where shard ``k`` of a folder is saved."""
    return folder / f"shard-{k:06d}.state"


def shard_files(folder: Path) -> list[Path]:
    """The saved shard states of a folder, in shard order."""
    return sorted(folder.glob("shard-*.state"))


def shard_rows(folder: Path) -> Iterator[tuple[str, list]]:
    """``(detector, per-image rows)`` of every saved shard, in shard order: from the rows
    written when the shards were last merged (:func:`run_shards`), else from the states."""
    written = folder / ROWS_FILE
    if written.exists():
        with open(written) as f:
            for line in f:
                det, rows = json.loads(line)
                yield det, rows
        return
    for path in shard_files(folder):
        for r in load_shard(path).results:
            yield r.detector.name, r.rows


def shard_coco(folder: Path, name: str) -> CocoExport:
    """The COCO export of a dataset: the saved shards' exports merged in shard order."""
    return CocoExport.merge(name, (s.coco for s in map(load_shard, shard_files(folder)) if s.coco))


class ShardMerger:
    """Merges a folder's saved shards in shard order while the rest are being scored: each
    shard is added as soon as every shard before it is saved (or lost), so the end of a
    run waits only for the shards still out of order. The per-image rows go to
    :data:`ROWS_FILE` (removed at the start, replaced atomically at :meth:`finish`, so a
    failed run leaves none). Use as a context manager: leaving it removes the partial rows.

    Args:
        folder: where the shards are saved.
        n_shards: the dataset's number of shards.
        pending: the shards not saved yet (the rest were saved by an earlier run).
    """

    def __init__(self, folder: Path, n_shards: int, pending: Iterable[int]) -> None:
        self.folder = folder
        self._ready = set(range(n_shards)) - set(pending)
        self._lost: set[int] = set()
        self._next = 0
        self._merged: list[Path] = []
        self._held: dict[int, ShardState] = {}
        self._out: list[DetectorResult] | None = None
        (folder / ROWS_FILE).unlink(missing_ok=True)
        self._tmp = folder / f".{ROWS_FILE}.{os.getpid()}.tmp"
        self._rows: IO[str] = open(self._tmp, "w")  # noqa: SIM115 (closed in __exit__)

    def __enter__(self) -> ShardMerger:
        return self

    def __exit__(self, *exc) -> None:
        self._rows.close()
        self._tmp.unlink(missing_ok=True)

    def saved(self, k: int, state: ShardState | None = None) -> None:
        """Shard ``k`` is saved (or, ``state``, scored and kept in memory, not saved): merge
        every shard now in order."""
        self._ready.add(k)
        if state is not None:
            self._held[k] = state
        self._drain()

    def lost(self, k: int) -> None:
        """Shard ``k`` failed for good (skipped): merge past it."""
        self._lost.add(k)
        self._drain()

    def _drain(self) -> None:
        while self._next in self._ready or self._next in self._lost:
            if self._next in self._held:
                self._out = _add(self._out, self._held.pop(self._next).results, self._rows)
            elif self._next in self._ready:
                path = shard_path(self.folder, self._next)
                self._out = _add(self._out, load_shard(path).results, self._rows)
                self._merged.append(path)
            self._next += 1

    def finish(self) -> list[DetectorResult]:
        """The merged results of every saved shard of the folder (merged again from the
        folder, should it hold any shard that was not seen as it was saved)."""
        self._drain()
        if self._merged != shard_files(self.folder):
            self._rows.seek(0)
            self._rows.truncate()
            self._out = merge((load_shard(p).results for p in shard_files(self.folder)), self._rows)
        self._rows.close()
        os.replace(self._tmp, self.folder / ROWS_FILE)
        return self._out or []
