"""Shards as the unit of work: a dataset's items are cut into fixed-size shards, each shard is
scored into mergeable detector states saved atomically beside the results, and the final
tables are the merge of the shard states (in shard order, so any split, worker count or
resume gives identical tables).

Engines: shards run in this process (``workers=1``) or in ``workers`` spawned processes,
each with ``cores // workers`` torch threads so workers never oversubscribe the machine.
A saved shard is never recomputed, which is what ``--resume`` relies on.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import zlib
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import torch
from torch.utils.data import Dataset, Subset
from tqdm.auto import tqdm

from eval.runner import DetectorResult, Scoring, evaluate

__all__ = ["ShardJob", "merge", "run_shards", "shard_ranges"]


@dataclass(frozen=True)
class ShardJob:
    """Everything a worker needs to score shards of one dataset (picklable: the dataset
    object holds paths and options, never open files)."""

    name: str
    dataset: Dataset
    indices: Sequence[int]
    specs: list
    scoring: Scoring
    batch_size: int = 16
    preprocess: Callable | None = None
    shard_size: int = 256


def shard_ranges(n: int, size: int) -> list[range]:
    """Consecutive positions ``[k * size, (k + 1) * size)`` covering ``0 .. n - 1``."""
    return [range(k, min(k + size, n)) for k in range(0, n, size)]


def _score_shard(job: ShardJob, k: int, on_batch=None) -> list[DetectorResult]:
    rng = shard_ranges(len(job.indices), job.shard_size)[k]
    part = Subset(job.dataset, [job.indices[i] for i in rng])
    return evaluate(
        part,
        job.specs,
        batch_size=job.batch_size,
        preprocess=job.preprocess,
        scoring=job.scoring,
        name=job.name,
        progress=False,
        on_batch=on_batch,
    )


def _save(path: Path, results: list[DetectorResult]) -> None:
    """Write a shard state atomically: a temporary name in the same folder, then rename."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as f:
        f.write(zlib.compress(pickle.dumps(results, protocol=pickle.HIGHEST_PROTOCOL), 1))
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _load(path: Path) -> list[DetectorResult]:
    with open(path, "rb") as f:
        return pickle.loads(zlib.decompress(f.read()))


def merge(parts: Sequence[list[DetectorResult]]) -> list[DetectorResult]:
    """Add shard results detector by detector, in shard order."""
    out = None
    for part in parts:
        out = part if out is None else [a + b for a, b in zip(out, part, strict=True)]
    return out or []


def _init_worker(threads: int) -> None:
    torch.set_num_threads(threads)


def _worker(job: ShardJob, k: int, path: Path) -> int:
    _save(path, _score_shard(job, k))
    return len(shard_ranges(len(job.indices), job.shard_size)[k])


def _pending(job: ShardJob, folder: Path) -> Iterator[tuple[int, Path]]:
    for k in range(len(shard_ranges(len(job.indices), job.shard_size))):
        path = folder / f"shard-{k:06d}.pkl"
        if not path.exists():
            yield k, path


def run_shards(
    job: ShardJob,
    folder: Path,
    *,
    workers: int = 1,
    progress: bool = True,
    on_batch=None,
) -> tuple[list[DetectorResult], dict]:
    """Score every shard not yet saved in ``folder``, then merge all saved shards.

    Returns the merged results (``rows`` read back shard by shard) and counts
    ``{"shards", "done", "skipped"}`` (skipped = found already saved, e.g. on resume).
    """
    folder.mkdir(parents=True, exist_ok=True)
    n_shards = len(shard_ranges(len(job.indices), job.shard_size))
    todo = list(_pending(job, folder))
    bar = tqdm(total=len(job.indices), desc=job.name, disable=not progress, unit="img")
    sizes = [len(r) for r in shard_ranges(len(job.indices), job.shard_size)]
    bar.update(len(job.indices) - sum(sizes[k] for k, _ in todo))
    if workers == 1:
        for k, path in todo:
            _save(path, _score_shard(job, k, on_batch))
            bar.update(sizes[k])
    else:
        threads = max(1, (os.cpu_count() or 1) // workers)
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_init_worker,
                                 initargs=(threads,)) as pool:  # fmt: skip
            futures = [pool.submit(_worker, job, k, path) for k, path in todo]
            for f in as_completed(futures):
                bar.update(f.result())
    bar.close()
    parts = [_load(folder / f"shard-{k:06d}.pkl") for k in range(n_shards)]
    merged = merge(parts) if parts else [DetectorResult(s, job.scoring) for s in job.specs]
    return merged, {"shards": n_shards, "done": len(todo), "skipped": n_shards - len(todo)}
