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

import multiprocessing
import os
import signal
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path

import torch
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
statefile.register(RocAccumulator, transient=("_log_grid",))
statefile.register(CocoState, transient=("_cache", "_consolidated"))
statefile.register(ScrCounts)
statefile.register(ErrorCounts)


def _save(path: Path, state: ShardState) -> None:
    """Write a shard state atomically (see :func:`_write`), as data only
    (:mod:`torchsar_eval.statefile`)."""
    _write(path, statefile.dumps(state))


def _load(path: Path) -> ShardState:
    """A saved shard state: data only, its content hash checked (``CorruptStateError``)."""
    with open(path, "rb") as f:
        state = statefile.loads(f.read(), f"shard state {path}")
    if not isinstance(state, ShardState):
        raise statefile.CorruptStateError(f"shard state {path} does not hold a shard")
    return state


def merge(parts: Iterable[list[DetectorResult]]) -> list[DetectorResult]:
    """Add shard results detector by detector, in shard order (one shard in memory at a
    time; the per-image rows are dropped: :func:`shard_rows` streams them from disk)."""
    out = None
    for part in parts:
        for r in part:
            r.rows = []
        out = part if out is None else [a + b for a, b in zip(out, part, strict=True)]
    return out or []


def shard_files(folder: Path) -> list[Path]:
    """The saved shard states of a folder, in shard order."""
    return sorted(folder.glob("shard-*.state"))


def shard_rows(folder: Path) -> Iterator[tuple[str, list]]:
    """``(detector, per-image rows)`` of every saved shard, in shard order."""
    for path in shard_files(folder):
        for r in _load(path).results:
            yield r.detector.name, r.rows


def shard_coco(folder: Path, name: str) -> CocoExport:
    """The COCO export of a dataset: the saved shards' exports merged in shard order."""
    return CocoExport.merge(name, (s.coco for s in map(_load, shard_files(folder)) if s.coco))


def _init_worker(threads: int) -> None:
    """Worker set-up: its share of the cores, and Ctrl-C left to the parent (which stops
    the pool) instead of a traceback per worker."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    torch.set_num_threads(threads)


def _scored(job: ShardJob, k: int) -> bytes:
    """A shard's state as the bytes of its state file (what a worker sends back)."""
    return statefile.dumps(_score_shard(job, k))


def _write(path: Path, data: bytes) -> None:
    """Save shard bytes atomically: a temporary name in the same folder, then rename. A
    failure to save (a full disk) stops the run: it is no fault of the shard's."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        reason = exc.strerror or exc
        raise EvalError(f"cannot save {path.name} in {path.parent} ({reason})") from exc


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
                _write(path, data)
                break
        bar.update(sizes[k])


_DIED = "a worker process died (killed or out of memory)"


def _processes(job, todo, bar, sizes, fail, workers: int) -> None:
    """Shards in ``workers`` spawned processes, at most ``workers`` at a time, a failed shard
    resubmitted once. A worker that dies (killed, out of memory) breaks the pool: the shards
    that were running are run again one at a time, each in a fresh process of its own (so a
    shard that kills its worker is told from those that only shared the pool with it and
    fails alone), and the rest go on in a fresh pool. Leaving early (an error, Ctrl-C,
    SIGTERM) stops the pool at once instead of waiting for running shards."""
    check_portable(job.detectors)
    threads = max(1, (os.cpu_count() or 1) // workers)
    workers = min(workers, len(todo))  # no idle processes
    paths = dict(todo)
    queue = list(paths)
    while queue:
        suspects = _pool_round(job, queue, paths, bar, sizes, fail, workers, threads)
        if suspects:
            warnings.warn(f"{_DIED}: running its {len(suspects)} shard(s) again one at a "
                          "time", RuntimeWarning, stacklevel=2)  # fmt: skip
        for k in suspects:
            _pool_round(job, [k], paths, bar, sizes, fail, 1, threads, solo=True)


def _pool_round(job, queue, paths, bar, sizes, fail, workers, threads, solo=False) -> list:
    """Run the shards of ``queue`` (consumed) in one pool of ``workers`` processes until
    they are done or the pool breaks; returns the shards that were running when it broke
    (with ``solo``, the shard is failed instead and ``[]`` returned)."""
    ctx = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(workers, mp_context=ctx, initializer=_init_worker,
                               initargs=(threads,))  # fmt: skip
    finished, broken = False, []
    running: dict = {}
    try:
        while queue or running:
            try:
                while queue and len(running) < workers:
                    running[pool.submit(_scored, job, queue[0])] = queue[0]
                    queue.pop(0)
            except BrokenProcessPool:  # broke before we noticed: settle what ran
                done = set(running)
                if not running:  # no worker even started
                    broken.append(queue.pop(0))
            else:
                done, _ = wait(running, return_when=FIRST_COMPLETED)
            for fut in done:
                k = running.pop(fut)
                try:
                    data = fut.result()
                except BrokenProcessPool:
                    broken.append(k)
                    continue
                except Exception as exc:
                    if fail.again(k, exc):
                        queue.insert(0, k)
                        continue
                else:
                    _write(paths[k], data)
                bar.update(sizes[k])
            if broken:
                broken += running.values()
                running.clear()
                break
        finished = True
    finally:
        if not finished or broken:  # do not wait for running shards
            for proc in list(getattr(pool, "_processes", {}).values()):
                proc.terminate()
        pool.shutdown(wait=finished and not broken, cancel_futures=True)
    if solo and broken:
        (k,) = broken
        fail(k, RuntimeError(_DIED))
        bar.update(sizes[k])
        return []
    return sorted(broken)


def _ray(job, todo, bar, sizes, fail, address: str | None) -> None:
    from torchsar_eval.ray_engine import run_on_ray

    def saved(k: int, path: Path, data: bytes | None) -> None:
        if data is not None:
            _write(path, data)
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
    merged = merge(_load(p).results for p in shard_files(folder))
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
