"""Tiles as the unit of work of ``detect``: each finished tile leaves a compact record (its
components' aggregates and the labels of its core's four edge lines,
:meth:`torchsar.tiling.SeamMerger.summarise`) saved atomically as a data-only state file
(:mod:`torchsar_eval.statefile`: a compressed NPZ with a content hash, never pickle) in
the run's staging folder. The driver merges the records of a scene in raster tile order,
so the table is byte-identical whatever the worker count, the order tiles finished in, or
how many runs (``--resume``) it took.

Workers: tiles run in this process (``workers=1``) or in ``workers`` spawned processes,
each with ``cores // workers`` torch threads, at most ``workers`` tasks at a time (a task is
a few consecutive tiles). A worker that dies (killed, out of memory) breaks the pool: the
tasks that were running run again one at a time in fresh processes, so a task that kills
its worker fails alone, with an error naming its tiles; the others go on in a fresh pool.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path

import pandas as pd

from torchsar_eval import statefile
from torchsar_eval.commands.detect.plan import DetectJob, min_size
from torchsar_eval.errors import EvalError
from torchsar_eval.pool import DIED, run_in_processes

__all__ = [
    "chunks",
    "close_readers",
    "load_record",
    "pending",
    "record_path",
    "run_tasks",
    "run_tiles",
    "scene_objects",
    "scene_reader",
]

Task = tuple[DetectJob, list[tuple[int, int]], Path]
"""A job, the indices of some of its scene's tiles, and the folder of their records."""

_READER: dict[str, object] = {}
"""The scene reader open in this process (one at a time)."""


def record_path(folder: Path, index: tuple[int, int]) -> Path:
    """Where tile ``index``'s record is saved."""
    return folder / f"tile-{index[0]:05d}-{index[1]:05d}.state"


def scene_reader(job: DetectJob) -> object:
    """The job's scene, opened for intensity windows (kept open in this process)."""
    from torchsar.io import open_scene

    sc = job.scene
    if sc.path not in _READER:
        close_readers()
        _READER[sc.path] = open_scene(sc.path, sample_type=sc.sample_type, as_intensity=True)
    return _READER[sc.path]


def close_readers() -> None:
    """Close the scene reader this process holds."""
    while _READER:
        _READER.popitem()[1].close()  # type: ignore[attr-defined]


def _iterate(job: DetectJob, indices: list[tuple[int, int]]):
    from torchsar.tiling import iter_region_tiles, iter_tiles, operator

    reader = scene_reader(job)
    if job.detector == "region":
        return iter_region_tiles(
            reader, tile=job.tile, device=job.device, only=indices, **job.options
        )
    op = operator(job.detector, **job.options)
    if job.clutter_mean is not None:
        op = op.with_options(clutter_mean=job.clutter_mean)
    return iter_tiles(reader, op, tile=job.tile, batch=job.batch, device=job.device, only=indices)


def run_tiles(job: DetectJob, indices: list[tuple[int, int]]) -> list[tuple[tuple, bytes]]:
    """Run the tiles ``indices`` of the job's scene; each tile's record as state-file bytes
    (what a worker sends back), by tile index."""
    from torchsar.tiling import SeamMerger

    merger = SeamMerger(job.scene.shape, job.connectivity)
    out = []
    for t, res in _iterate(job, indices):
        record = merger.summarise(t, res["mask"], res["statistic"])
        out.append((t.index, statefile.dumps(record)))
    return sorted(out)


def _task(job: DetectJob, indices: list[tuple[int, int]]) -> tuple[str, object]:
    """:func:`run_tiles` in a worker: a library error (bad data in a tile, a region tile
    that does not settle) comes back as its message, to be raised as a user error."""
    from torchsar.errors import TorchSARError

    try:
        return "ok", run_tiles(job, indices)
    except TorchSARError as exc:
        return "error", f"{type(exc).__name__}: {exc}"


def load_record(path: Path) -> dict:
    """A saved tile record (data only, content hash checked: ``CorruptStateError``)."""
    with open(path, "rb") as f:
        rec = statefile.loads(f.read(), f"tile record {path}")
    if not isinstance(rec, dict) or not {"index", "n", "edges", "aggregates"} <= set(rec):
        raise statefile.CorruptStateError(f"tile record {path} does not hold a tile")
    return rec


def pending(job: DetectJob, folder: Path) -> list[tuple[int, int]]:
    """The tiles of the job's scene without a usable record (a corrupt one is deleted,
    with a warning naming it, and its tile run again)."""
    todo = []
    for index in job.scene.tiles():
        path = record_path(folder, index)
        if path.exists():
            try:
                load_record(path)
                continue
            except statefile.CorruptStateError as exc:
                warnings.warn(f"{exc}: running that tile again", RuntimeWarning, stacklevel=2)
                path.unlink()
        todo.append(index)
    return todo


def _done(task: Task, result: tuple[str, object], bar) -> None:
    """Save a finished task's records (or raise its error)."""
    job, indices, folder = task
    kind, value = result
    if kind == "error":
        raise EvalError(f"scene {job.scene.scene_id}, tiles {_tiles_text(indices)}: {value}")
    for index, data in value:  # type: ignore[union-attr]
        statefile.save(record_path(folder, index), data)
    bar.update(len(indices))


def _tiles_text(indices: list[tuple[int, int]]) -> str:
    return ", ".join(f"{i},{j}" for i, j in indices)


def run_tasks(tasks: list[Task], workers: int, bar, fn: Callable = _task) -> None:
    """Run every task, saving each tile's record as its task finishes (see the module
    docstring for workers and dead workers). ``fn(job, indices)`` runs one task (a
    module-level function: workers import it)."""
    if workers == 1:
        for task in tasks:
            _done(task, fn(task[0], task[1]), bar)
        return

    def died(k: int) -> None:
        job, indices, _ = tasks[k]
        raise EvalError(
            f"scene {job.scene.scene_id}, tiles {_tiles_text(indices)}: {DIED} "
            "twice; the other tiles' records are kept"
        )

    run_in_processes(
        fn,
        {k: (t[0], t[1]) for k, t in enumerate(tasks)},
        workers,
        on_result=lambda k, result: _done(tasks[k], result, bar),
        on_died=died,
        what="task",
    )


def scene_objects(job: DetectJob, folder: Path) -> pd.DataFrame:
    """The object table of a scene from its saved records, merged in raster tile order
    (what :func:`torchsar.tiling.scene_objects` gives on the same scene and options)."""
    from torchsar.tiling import SeamMerger

    merger = SeamMerger(job.scene.shape, job.connectivity)
    for index in job.scene.tiles():
        path = record_path(folder, index)
        rec = load_record(path)
        if tuple(int(v) for v in rec["index"]) != index:
            raise statefile.CorruptStateError(f"tile record {path} holds tile {rec['index']}")
        merger.merge(rec)
    table = merger.table()
    return table[table["area"] >= min_size(job.detector, job.options)].reset_index(drop=True)


def chunks(indices: list[tuple[int, int]], size: int) -> list[list[tuple[int, int]]]:
    """Consecutive runs of ``size`` tiles (raster order), the tasks of a scene."""
    return [indices[k : k + size] for k in range(0, len(indices), size)]
