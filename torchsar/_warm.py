"""Compile every numba kernel for the common input types ahead of use.

numba compiles a kernel the first time it is called with new argument types and keeps the
machine code in its on-disk cache (``__pycache__`` beside the sources). On a fresh install
that first call costs about three minutes of one core for all kernels together; :func:`warm`
(run by ``make setup`` through ``scripts/warm_kernels.py``) pays it once, so the first
evaluation, detector call or test run does not. It runs every compiled path (the window
CFARs, OS-CFAR, the speckle filters, the region CFAR, object labelling and closing, the
matching, the pixel ROC) on tiny float32 and float64 batches (the window CFARs with and
without a valid mask), as :data:`TASKS` lists them. With ``workers > 1`` the tasks run in
that many processes, and the workers' writes into numba's cache are made one at a time
(numba's own cache can give two signatures compiled at once the same file). Without numba
(or with ``TORCHSAR_NUMBA=0``) it does nothing. :func:`warm_tables` computes the K and G0
CFARs' default design tables into their on-disk cache.
"""

from __future__ import annotations

import multiprocessing
import os
import tempfile
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool

import torch

from torchsar import _jit

__all__ = ["TASKS", "warm", "warm_tables"]

_WINDOW = ("os", "two_parameter", "go", "ca", "vi", "ac", "lognormal", "so")
_FILTERS = ("lee", "frost", "enhanced_lee", "enhanced_frost", "gamma_map")
TASKS = (
    *("os", "two_parameter", "go", "ca", "lee", "region", "vi", "ac", "lognormal", "so"),
    *("frost", "scoring", "enhanced_lee", "enhanced_frost", "gamma_map", "os_mask"),
)
"""The warm-up's units of work, the longest to compile first (so that parallel workers end
together): a window CFAR by name (with and without a valid mask), a speckle filter by name,
``"os_mask"`` (OS-CFAR's counting decision), ``"region"`` and ``"scoring"`` (object
labelling and closing, the ground truth, the matching, the pixel ROC)."""


def _images(dtype: torch.dtype) -> torch.Tensor:
    g = torch.Generator().manual_seed(0)
    x = torch.empty(2, 1, 40, 40, dtype=torch.float64).exponential_(generator=g)
    x[..., 20, 20] = 80.0
    x[..., 10:13, 28:31] = 40.0
    return x.to(dtype)


def _scoring(x: torch.Tensor) -> None:
    """The object stage and the metrics' compiled paths on the detections of ``x``."""
    from torchsar import cfar
    from torchsar.metrics import Matching, RocAccumulator, ground_truth, match_batch
    from torchsar.objects import ObjectRules, discriminate

    det = cfar.ca(x)  # detects the bright spots: objects to label and close
    for closing in (0, 2):
        obj = discriminate(det.statistic, det.threshold, rules=ObjectRules(closing=closing))
    ids = torch.zeros(x.shape[0], *x.shape[-2:], dtype=torch.int64)
    ids[:, 18:23, 18:23] = 1
    gt = ground_truth(ids.numpy())
    for kind in ("mask", "centroid"):  # the greedy assignment and the pixel joins
        match_batch(obj, gt, Matching(kind=kind))
    acc = RocAccumulator()
    target = torch.zeros_like(x, dtype=torch.bool)
    target[..., 18:23, 18:23] = True
    acc.update(det.statistic, target, detected=det.mask)
    with_inf = det.statistic.clone()
    with_inf[..., 0, 0] = -torch.inf  # the batch's finite range found by the kernel
    valid = torch.ones_like(target)
    valid[..., :4, :] = False
    acc.update(with_inf, target, ~valid, detected=det.mask)


def run_task(task: str, dtype: torch.dtype) -> None:
    """One of :data:`TASKS` on a tiny batch of ``dtype`` images."""
    from torchsar import cfar, speckle
    from torchsar.region import region_cfar

    x = _images(dtype)
    if task in _WINDOW:
        valid = torch.ones_like(x, dtype=torch.bool)
        valid[..., :4, :] = False
        for mask in (None, valid):
            getattr(cfar, task)(x, valid=mask)
    elif task in _FILTERS:
        speckle.FILTERS[task](x, window=3)
    elif task == "os_mask":
        cfar.os_mask(x)
    elif task == "region":
        region_cfar(x)
    elif task == "scoring":
        _scoring(x)
    else:
        raise ValueError(f"unknown warm-up task {task!r}")


def warm(
    dtypes: tuple[torch.dtype, ...] = (torch.float32, torch.float64),
    workers: int = 1,
    tasks: tuple[str, ...] = TASKS,
) -> float:
    """Run every task of ``tasks`` (by default all of :data:`TASKS`) once per image type of
    ``dtypes``, in ``workers`` processes (one: in this one); the seconds it took (0 when
    the kernels are off)."""
    if not _jit.enabled():
        return 0.0
    start = time.perf_counter()
    jobs = [(task, dtype) for task in tasks for dtype in dtypes]
    if workers > 1 and _serial_saves_available():
        try:
            _in_processes(jobs, workers)
            return time.perf_counter() - start
        except (OSError, BrokenProcessPool) as err:  # no processes here: in this one
            msg = f"warm-up workers failed ({err}); compiling in this process"
            warnings.warn(msg, RuntimeWarning, stacklevel=2)
    for task, dtype in jobs:
        run_task(task, dtype)
    return time.perf_counter() - start


def _in_processes(jobs: list[tuple[str, torch.dtype]], workers: int) -> None:
    """The warm-up's ``jobs`` in ``workers`` spawned processes (:func:`_worker`)."""
    lock = os.path.join(tempfile.gettempdir(), f"torchsar-warm-{os.getpid()}.lock")
    ctx = multiprocessing.get_context("spawn")
    try:
        with ProcessPoolExecutor(
            min(workers, len(jobs)), mp_context=ctx, initializer=_worker, initargs=(lock,)
        ) as pool:
            list(pool.map(run_task, *zip(*jobs, strict=True)))
    finally:
        if os.path.exists(lock):
            os.unlink(lock)


def _serial_saves_available() -> bool:
    """Whether a worker can make numba's cache writes one at a time (an advisory file lock,
    and the cache's write method where this numba keeps it); else the warm-up runs in one
    process."""
    try:
        import fcntl  # noqa: F401

        from numba.core.caching import IndexDataCacheFile
    except ImportError:
        return False
    return callable(getattr(IndexDataCacheFile, "save", None))


def _worker(lock: str) -> None:
    """A warm-up worker's set-up: one torch thread, and numba's cache writes (the index
    then the data of one signature) one at a time across the workers, under the file lock
    ``lock``. Without it, two workers adding different signatures of one function at once
    could both take its first free data file, and the index name the other's code."""
    import fcntl

    from numba.core import caching

    torch.set_num_threads(1)
    save = caching.IndexDataCacheFile.save

    def save_alone(self, key, data):
        with open(lock, "a") as f:
            fcntl.flock(f, fcntl.LOCK_EX)
            try:
                return save(self, key, data)
            finally:
                fcntl.flock(f, fcntl.LOCK_UN)

    caching.IndexDataCacheFile.save = save_alone


def warm_tables() -> float:
    """Compute the K and G0 CFARs' log-t factors at their default design (``pfa = 1e-3``,
    one look, every ring size of the default window, borders included) into the on-disk
    cache (:func:`torchsar.cfar.log_t.log_t_exact`); the seconds it took. Kernels on or
    off, the first K or G0 detection then costs no calibration."""
    from torchsar import cfar

    start = time.perf_counter()
    x = _images(torch.float32)
    for detector in (cfar.k, cfar.g0):
        detector(x)
    return time.perf_counter() - start
