"""Shards as the unit of work: a dataset's items are cut into fixed-size shards, each shard is
scored into mergeable detector states saved atomically beside the results, and the final
tables are the merge of the shard states (in shard order, so any split, worker count or
resume gives identical tables; :mod:`torchsar_eval.shard_states` merges them while the rest
are scored).

Engines: shards run in this process (``workers=1``), in ``workers`` spawned processes, each
with ``cores // workers`` torch threads so workers never oversubscribe the machine, or as
Ray tasks (one CPU and one torch thread each). Whatever the engine, a failed shard is run
once more before it counts as failed.
A saved shard is never recomputed, which is what ``--resume`` relies on.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from torch.utils.data import Dataset
from tqdm.auto import tqdm

from torchsar_eval import statefile
from torchsar_eval.batches import Indexed
from torchsar_eval.coco import CocoExport
from torchsar_eval.detector import check_portable
from torchsar_eval.errors import EvalError
from torchsar_eval.labels import short_label
from torchsar_eval.memory import release_memory, tune_allocator
from torchsar_eval.objects_only import objects_only, score_objects
from torchsar_eval.pool import DIED, run_in_processes
from torchsar_eval.ray_engine import run_on_ray
from torchsar_eval.result import DetectorResult, Scoring
from torchsar_eval.runner import run_detectors
from torchsar_eval.settings import Execution
from torchsar_eval.shard_states import (
    ROWS_FILE,
    ShardMerger,
    ShardState,
    load_shard,
    merge,
    shard_coco,
    shard_files,
    shard_path,
    shard_rows,
)

__all__ = [
    "ROWS_FILE",
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
    path travel as that reference). ``execution`` is the run's, whole: batches, shard size,
    device and ``skip_bad`` for the worker; workers, engine and progress for the driver."""

    name: str
    dataset: Dataset
    indices: Sequence[int]
    detectors: list
    scoring: Scoring
    execution: Execution = field(default_factory=Execution)
    preprocess: Callable | None = None
    export_coco: bool = False
    default_class: str = "target"


def shard_ranges(n: int, size: int) -> list[range]:
    """Consecutive positions ``[k * size, (k + 1) * size)`` covering ``0 .. n - 1``."""
    return [range(k, min(k + size, n)) for k in range(0, n, size)]


def _score_shard(job: ShardJob, k: int) -> ShardState:
    tune_allocator()
    ex = job.execution
    rng = shard_ranges(len(job.indices), ex.shard_size)[k]
    if objects_only(job) and not job.export_coco:  # saved boxes from annotations: no pixel
        return ShardState(score_objects(job, [job.indices[i] for i in rng], job.name))
    part = Indexed(job.dataset, [job.indices[i] for i in rng])
    coco = CocoExport(job.name) if job.export_coco else None
    results = run_detectors(
        part,
        job.detectors,
        batch_size=ex.batch_size,
        preprocess=job.preprocess,
        scoring=job.scoring,
        name=job.name,
        progress=False,
        on_batch=None if coco is None else coco.add,
        device=ex.device,
        default_class=job.default_class,
        skip_bad=ex.skip_bad,
        overlap=ex.overlap,
    )
    release_memory()
    return ShardState(results, coco)


def _scored(job: ShardJob, k: int) -> bytes:
    """A shard's state as the bytes of its state file (what a worker sends back)."""
    return statefile.dumps(_score_shard(job, k))


def _pending(job: ShardJob, folder: Path) -> list[tuple[int, Path]]:
    """The shards to score: those not saved, and those whose saved state is corrupt
    (scored again, with a warning naming the file)."""
    n_shards = len(shard_ranges(len(job.indices), job.execution.shard_size))
    paths = [(k, shard_path(folder, k)) for k in range(n_shards)]
    return [(k, p) for k, p in paths if not _usable(p)]


def _usable(path: Path) -> bool:
    if not path.exists():
        return False
    try:
        load_shard(path)
    except statefile.CorruptStateError as exc:
        warnings.warn(f"{exc}: scoring that shard again", RuntimeWarning, stacklevel=3)
        path.unlink()
        return False
    return True


class _Failures:
    """Shards that failed: each gets one retry, then the failure is fatal or, with
    ``skip_bad``, recorded (and ``on_lost`` told)."""

    def __init__(self, skip_bad: bool, on_lost: Callable[[int], None]) -> None:
        self.skip_bad = skip_bad
        self.on_lost = on_lost
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
        self.on_lost(k)


class _Track:
    """A run's finished shards: each saved one goes to the merger, and every settled one
    (saved or failed) moves the progress bar. Without ``persist`` (a run that cannot be
    resumed: its folder is temporary) a state scored in this process is merged as it is,
    neither encoded nor written."""

    def __init__(self, bar, sizes: list[int], merger: ShardMerger, persist: bool) -> None:
        self.bar, self.sizes, self.merger, self.persist = bar, sizes, merger, persist

    def saved(self, k: int, path: Path, data: bytes | ShardState) -> None:
        if isinstance(data, ShardState):  # scored here, not to be saved
            self.merger.saved(k, data)
        else:
            statefile.save(path, data)
            self.merger.saved(k)
        self.settled(k)

    def settled(self, k: int) -> None:
        self.bar.update(self.sizes[k])


def _local(job, todo, track: _Track, fail: _Failures) -> None:
    for k, path in todo:
        while True:
            try:
                data = _scored(job, k) if track.persist else _score_shard(job, k)
            except KeyboardInterrupt:
                raise
            except Exception as exc:
                if not fail.again(k, exc):
                    track.settled(k)
                    break
            else:
                track.saved(k, path, data)
                break


def _processes(job, todo, track: _Track, fail: _Failures, workers: int) -> None:
    """Shards in ``workers`` spawned processes (:func:`torchsar_eval.pool.run_in_processes`:
    a dead worker's shards run again one at a time, so only the shard that kills its worker
    fails), a failed shard resubmitted once."""
    check_portable(job.detectors)
    paths = dict(todo)

    def failed(k: int, exc: BaseException) -> bool:
        if fail.again(k, exc):
            return True
        track.settled(k)
        return False

    def died(k: int) -> None:
        fail(k, RuntimeError(DIED))
        track.settled(k)

    run_in_processes(
        _scored,
        {k: (job, k) for k in paths},
        workers,
        on_result=lambda k, data: track.saved(k, paths[k], data),
        on_error=failed,
        on_died=died,
        what="shard",
    )


def _ray(job, todo, track: _Track, fail: _Failures, address: str | None) -> None:

    def done(k: int, path: Path, data: bytes | None) -> None:
        if data is None:  # failed (and settled by ``fail``)
            track.settled(k)
        else:
            track.saved(k, path, data)

    run_on_ray(job, todo, done, fail, address, _scored)


def run_shards(
    job: ShardJob, folder: Path, *, persist: bool = True
) -> tuple[list[DetectorResult], dict]:
    """Score every shard not yet saved in ``folder`` and merge all saved shards (in shard
    order, each as soon as the shards before it are saved).

    Args:
        job: the dataset, detectors, scoring and execution: its ``engine`` (``"local"``:
            this process or ``workers`` processes; ``"ray"``: Ray tasks at ``address``),
            ``skip_bad`` (record failed shards and merge the rest instead of stopping) and
            ``progress`` (one bar over images).
        folder: where shard states are saved (and found again on resume).
        persist: save every shard's state in ``folder`` (``False``: shards scored in this
            process are merged from memory; for a temporary folder, never resumed).

    Returns:
        The merged results and counts ``{"shards", "done", "skipped", "retried", "failed",
        "scored_images", "reused_images"}`` (skipped = found saved already, e.g. on resume;
        retried = shards that failed once and were run again; failed = list of shards that
        failed twice; the images of the shards scored now and of those found saved).
    """
    ex = job.execution
    folder.mkdir(parents=True, exist_ok=True)
    sizes = [len(r) for r in shard_ranges(len(job.indices), ex.shard_size)]
    todo = _pending(job, folder)
    bar = tqdm(
        total=len(job.indices), desc=short_label(job.name), disable=not ex.progress, unit="img"
    )
    bar.update(len(job.indices) - sum(sizes[k] for k, _ in todo))
    with ShardMerger(folder, len(sizes), (k for k, _ in todo)) as merger:
        track, fail = _Track(bar, sizes, merger, persist), _Failures(ex.skip_bad, merger.lost)
        try:
            if ex.engine == "ray":
                _ray(job, todo, track, fail, ex.address)
            elif ex.workers == 1:
                _local(job, todo, track, fail)
            else:
                _processes(job, todo, track, fail, ex.workers)
        finally:
            bar.close()
        merged = merger.finish()
    merged = merged or [
        DetectorResult(d, job.scoring, default_class=job.default_class) for d in job.detectors
    ]
    lost = {f["shard"] for f in fail.failed}
    scored = sum(sizes[k] for k, _ in todo if k not in lost)
    reused = len(job.indices) - sum(sizes[k] for k, _ in todo)
    counts = {
        "shards": len(sizes),
        "done": len(todo) - len(fail.failed),
        "skipped": len(sizes) - len(todo),
        "retried": len(fail.retried),
        "failed": fail.failed,
        "scored_images": scored,
        "reused_images": reused,
    }
    return merged, counts
