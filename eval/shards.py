"""Shards as the unit of work: a dataset's items are cut into fixed-size shards, each shard is
scored into mergeable detector states saved atomically beside the results, and the final
tables are the merge of the shard states (in shard order, so any split, worker count or
resume gives identical tables).

Engines: shards run in this process (``workers=1``), in ``workers`` spawned processes, each
with ``cores // workers`` torch threads so workers never oversubscribe the machine, or as
Ray tasks (one CPU and one torch thread each). Whatever the engine, a failed shard is run
once more before it counts as failed.
A saved shard is never recomputed, which is what ``--resume`` relies on.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from torch.utils.data import Dataset
from tqdm.auto import tqdm

from torchsar.metrics import ObjectState, PixelCounts, RocAccumulator
from torchsar.metrics.coco_compat import CocoState
from torchsar.metrics.distance import LengthErrors
from torchsar.metrics.error_types import ErrorCounts
from torchsar.metrics.matching import Matching
from torchsar.metrics.object_state import KeyCounts
from torchsar.metrics.ranked import RankedDetections
from torchsar.metrics.scr import ScrCounts
from torchsar.objects import ObjectRules
from torchsar_eval import statefile
from torchsar_eval.batches import Indexed
from torchsar_eval.coco import CocoExport
from torchsar_eval.detector import check_portable
from torchsar_eval.errors import EvalError
from torchsar_eval.gallery import Cases, Gallery
from torchsar_eval.labels import short_label
from torchsar_eval.memory import release_memory, tune_allocator
from torchsar_eval.pool import DIED, run_in_processes
from torchsar_eval.result import DetectorName, DetectorResult, Scoring
from torchsar_eval.runner import run_detectors

__all__ = [
    "ShardJob",
    "ShardState",
    "merge",
    "run_shards",
    "shard_coco",
    "shard_files",
    "shard_ranges",
    "shard_rows",
]


@dataclass(frozen=True)
class ShardJob:
    """Everything a worker needs to score shards of one dataset (picklable: the dataset
    object holds paths and options, never open files; detectors resolved by name or import
    path travel as that reference)."""

    name: str
    dataset: Dataset
    indices: Sequence[int]
    detectors: list
    scoring: Scoring
    batch_size: int = 16
    preprocess: Callable | None = None
    shard_size: int = 256
    export_coco: bool = False
    device: str | None = None
    default_class: str = "target"
    skip_bad: bool = False


@dataclass
class ShardState:
    """What one shard leaves on disk: every detector's mergeable results and, with
    ``export_coco``, the shard's COCO ground truth and detections."""

    results: list[DetectorResult]
    coco: CocoExport | None = None


def shard_ranges(n: int, size: int) -> list[range]:
    """Consecutive positions ``[k * size, (k + 1) * size)`` covering ``0 .. n - 1``."""
    return [range(k, min(k + size, n)) for k in range(0, n, size)]


def _score_shard(job: ShardJob, k: int) -> ShardState:
    tune_allocator()
    rng = shard_ranges(len(job.indices), job.shard_size)[k]
    part = Indexed(job.dataset, [job.indices[i] for i in rng])
    coco = CocoExport(job.name) if job.export_coco else None
    results = run_detectors(
        part,
        job.detectors,
        batch_size=job.batch_size,
        preprocess=job.preprocess,
        scoring=job.scoring,
        name=job.name,
        progress=False,
        on_batch=None if coco is None else coco.add,
        device=job.device,
        default_class=job.default_class,
        skip_bad=job.skip_bad,
    )
    release_memory()
    return ShardState(results, coco)


for _cls in (
    ShardState,
    DetectorResult,
    DetectorName,
    Scoring,
    ObjectRules,
    Matching,
    PixelCounts,
    ObjectState,
    KeyCounts,
    RankedDetections,
    LengthErrors,
    CocoExport,
    Gallery,
    Cases,
):
    statefile.register(_cls)  # fmt: skip
statefile.register(RocAccumulator, transient=("_log_grid", "_starts"))
statefile.register(CocoState, transient=("_cache", "_consolidated"))
statefile.register(ScrCounts)
statefile.register(ErrorCounts)


def _save(path: Path, state: ShardState) -> None:
    """Write a shard state atomically, as data only (:mod:`torchsar_eval.statefile`)."""
    statefile.save(path, statefile.dumps(state))


def _load(path: Path) -> ShardState:
    """A saved shard state: data only, its content hash checked (``CorruptStateError``)."""
    with open(path, "rb") as f:
        state = statefile.loads(f.read(), f"shard state {path}")
    if not isinstance(state, ShardState):
        raise statefile.CorruptStateError(f"shard state {path} does not hold a shard")
    return state


ROWS_FILE = "rows.jsonl"
"""The per-image rows of a folder's shards, in shard order, written while they are merged."""


def merge(parts: Iterable[list[DetectorResult]], rows_to: IO[str] | None = None
          ) -> list[DetectorResult]:  # fmt: skip
    """Add shard results detector by detector, in shard order (one shard in memory at a
    time; the per-image rows are dropped, after being written to ``rows_to`` as JSON lines
    ``[detector, rows]`` when given: :func:`shard_rows` streams them from there)."""
    out = None
    for part in parts:
        for r in part:
            if rows_to is not None:
                rows_to.write(json.dumps([r.detector.name, list(r.rows)]) + "\n")
            r.rows = []
        out = part if out is None else [a + b for a, b in zip(out, part, strict=True)]
    return out or []


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
        for r in _load(path).results:
            yield r.detector.name, r.rows


def _merge_saved(folder: Path) -> list[DetectorResult]:
    """Merge the folder's saved shards, reading each once: the rows go to
    :data:`ROWS_FILE` (replaced atomically; removed first, so a failed merge leaves none)."""
    written = folder / ROWS_FILE
    written.unlink(missing_ok=True)
    tmp = folder / f".{ROWS_FILE}.{os.getpid()}.tmp"
    try:
        with open(tmp, "w") as f:
            merged = merge((_load(p).results for p in shard_files(folder)), f)
        os.replace(tmp, written)
    finally:
        tmp.unlink(missing_ok=True)
    return merged


def shard_coco(folder: Path, name: str) -> CocoExport:
    """The COCO export of a dataset: the saved shards' exports merged in shard order."""
    return CocoExport.merge(name, (s.coco for s in map(_load, shard_files(folder)) if s.coco))


def _scored(job: ShardJob, k: int) -> bytes:
    """A shard's state as the bytes of its state file (what a worker sends back)."""
    return statefile.dumps(_score_shard(job, k))


def _pending(job: ShardJob, folder: Path) -> list[tuple[int, Path]]:
    """The shards to score: those not saved, and those whose saved state is corrupt
    (scored again, with a warning naming the file)."""
    n_shards = len(shard_ranges(len(job.indices), job.shard_size))
    paths = [(k, folder / f"shard-{k:06d}.state") for k in range(n_shards)]
    return [(k, p) for k, p in paths if not _usable(p)]


def _usable(path: Path) -> bool:
    if not path.exists():
        return False
    try:
        _load(path)
    except statefile.CorruptStateError as exc:
        warnings.warn(f"{exc}: scoring that shard again", RuntimeWarning, stacklevel=3)
        path.unlink()
        return False
    return True


class _Failures:
    """Shards that failed: each gets one retry, then the failure is fatal or, with
    ``skip_bad``, recorded."""

    def __init__(self, skip_bad: bool) -> None:
        self.skip_bad = skip_bad
        self.failed: list[dict] = []
        self.retried: list[int] = []

    def again(self, k: int, exc: BaseException) -> bool:
        """Shard ``k`` failed with ``exc``: ``True`` when it runs once more (its first
        failure, counted), else the failure is settled (raised or recorded)."""
        if k not in self.retried and not isinstance(exc, KeyboardInterrupt):
            self.retried.append(k)
            return True
        self(k, exc)
        return False

    def __call__(self, k: int, exc: BaseException) -> None:
        if isinstance(exc, KeyboardInterrupt):
            raise exc
        if not self.skip_bad:
            raise EvalError(
                f"shard {k} failed: {exc} (pass {{opt:skip_bad}} to continue past it)"
            ) from exc
        self.failed.append({"shard": k, "error": f"{type(exc).__name__}: {exc}"})


def _local(job, todo, bar, sizes, fail) -> None:
    for k, path in todo:
        while True:
            try:
                data = _scored(job, k)
            except KeyboardInterrupt:
                raise
            except Exception as exc:
                if not fail.again(k, exc):
                    break
            else:
                statefile.save(path, data)
                break
        bar.update(sizes[k])


def _processes(job, todo, bar, sizes, fail, workers: int) -> None:
    """Shards in ``workers`` spawned processes (:func:`torchsar_eval.pool.run_in_processes`:
    a dead worker's shards run again one at a time, so only the shard that kills its worker
    fails), a failed shard resubmitted once."""
    check_portable(job.detectors)
    paths = dict(todo)

    def saved(k: int, data: bytes) -> None:
        statefile.save(paths[k], data)
        bar.update(sizes[k])

    def failed(k: int, exc: BaseException) -> bool:
        if fail.again(k, exc):
            return True
        bar.update(sizes[k])
        return False

    def died(k: int) -> None:
        fail(k, RuntimeError(DIED))
        bar.update(sizes[k])

    run_in_processes(_scored, {k: (job, k) for k in paths}, workers, on_result=saved,
                     on_error=failed, on_died=died, what="shard")  # fmt: skip


def _ray(job, todo, bar, sizes, fail, address: str | None) -> None:
    from torchsar_eval.ray_engine import run_on_ray

    def saved(k: int, path: Path, data: bytes | None) -> None:
        if data is not None:
            statefile.save(path, data)
        bar.update(sizes[k])

    run_on_ray(job, todo, saved, fail, address)


def run_shards(
    job: ShardJob,
    folder: Path,
    *,
    workers: int = 1,
    engine: str = "local",
    address: str | None = None,
    skip_bad: bool = False,
    progress: bool = True,
) -> tuple[list[DetectorResult], dict]:
    """Score every shard not yet saved in ``folder``, then merge all saved shards.

    Args:
        job: the dataset, detectors and scoring.
        folder: where shard states are saved (and found again on resume).
        workers: local worker processes (``engine="local"``).
        engine: ``"local"`` (this process or ``workers`` processes) or ``"ray"``.
        address: Ray cluster address (default: a local Ray instance).
        skip_bad: record failed shards and merge the rest instead of stopping.
        progress: one progress bar over images.

    Returns:
        The merged results and counts ``{"shards", "done", "skipped", "retried", "failed",
        "scored_images", "reused_images"}`` (skipped = found saved already, e.g. on resume;
        retried = shards that failed once and were run again; failed = list of shards that
        failed twice; the images of the shards scored now and of those found saved).
    """
    folder.mkdir(parents=True, exist_ok=True)
    sizes = [len(r) for r in shard_ranges(len(job.indices), job.shard_size)]
    todo = _pending(job, folder)
    fail = _Failures(skip_bad)
    bar = tqdm(total=len(job.indices), desc=short_label(job.name), disable=not progress,
               unit="img")  # fmt: skip
    bar.update(len(job.indices) - sum(sizes[k] for k, _ in todo))
    try:
        if engine == "ray":
            _ray(job, todo, bar, sizes, fail, address)
        elif workers == 1:
            _local(job, todo, bar, sizes, fail)
        else:
            _processes(job, todo, bar, sizes, fail, workers)
    finally:
        bar.close()
    merged = _merge_saved(folder)
    merged = merged or [DetectorResult(d, job.scoring, default_class=job.default_class)
                        for d in job.detectors]  # fmt: skip
    lost = {f["shard"] for f in fail.failed}
    scored = sum(sizes[k] for k, _ in todo if k not in lost)
    reused = len(job.indices) - sum(sizes[k] for k, _ in todo)
    counts = {"shards": len(sizes), "done": len(todo) - len(fail.failed),
              "skipped": len(sizes) - len(todo), "retried": len(fail.retried),
              "failed": fail.failed, "scored_images": scored,
              "reused_images": reused}  # fmt: skip
    return merged, counts
