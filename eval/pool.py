"""Work items in spawned worker processes, surviving a worker that dies: the one pool
mechanism of ``run`` (shards) and ``detect`` (tiles).

At most ``workers`` items run at a time. A worker that dies (killed, out of memory) breaks
the pool: the items that were running are run again one at a time, each in a fresh process
of its own (so the item that kills its worker is told from those that only shared the pool
with it), and the rest go on in a fresh pool. Leaving early (an error, Ctrl-C, SIGTERM)
stops the pool at once instead of waiting for running items. Workers ignore Ctrl-C (the
driver handles it) and get their share of the cores as torch threads. A pool whose workers
all die before they start (a script that runs an evaluation at its top level, re-run by
every spawned worker) is refused in one line that says so, not blamed on an item."""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import threading
import time
import warnings
from collections.abc import Callable, Hashable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

from torchsar_eval.errors import EvalError

__all__ = ["DIED", "NOT_STARTED", "run_in_processes"]

DIED = "a worker process died (killed or out of memory)"
NOT_STARTED = (
    "no worker process could start: each one re-imports the main script, so a script that "
    'runs an evaluation with workers must do it under `if __name__ == "__main__":` (the '
    "worker's own error is printed above)"
)


ORPHAN_CHECK_S = 0.5
"""How often a worker checks that its driver is alive (it exits within this of a kill)."""


def _watch_driver(driver: int) -> None:
    """End this worker when its driver is gone (killed with SIGKILL, nothing could tell
    the pool): a daemon thread watching the parent process id."""

    def watch() -> None:
        while os.getppid() == driver:
            time.sleep(ORPHAN_CHECK_S)
        os._exit(1)

    if os.getppid() != driver:
        os._exit(1)
    threading.Thread(target=watch, name="torchsar-driver-watch", daemon=True).start()


def _init_worker(threads: int, started, driver: int) -> None:
    _watch_driver(driver)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the driver's to handle
    with started.get_lock():  # this worker got past its start (the main script's import)
        started.value += 1
    # torch after the worker has started: its thread count is set before first use
    import torch

    torch.set_num_threads(threads)


def _reraise(key: Hashable, exc: BaseException) -> bool:
    raise exc


def run_in_processes(
    fn: Callable,
    items: dict[Hashable, tuple],
    workers: int,
    *,
    on_result: Callable[[Hashable, object], None],
    on_died: Callable[[Hashable], None],
    on_error: Callable[[Hashable, BaseException], bool] = _reraise,
    what: str = "item",
) -> None:
    """Run ``fn(*items[key])`` for every key in ``workers`` spawned processes (``fn`` a
    module-level function: workers import it), in key order as far as workers allow.

    Args:
        on_result: called in the driver with each finished key and its value.
        on_died: called with the key whose worker died again when it ran alone.
        on_error: called with a key whose ``fn`` raised; True runs it again (first in
            line), False settles it; by default the error is raised.
        what: the items' name in the warning about a dead worker.
    """
    threads = max(1, (os.cpu_count() or 1) // workers)
    queue = list(items)
    workers = min(workers, len(queue)) or 1  # no idle processes
    hooks = (on_result, on_error, on_died)
    while queue:
        suspects = _round(fn, items, queue, workers, threads, hooks)
        if suspects:
            warnings.warn(
                f"{DIED}: running its {len(suspects)} {what}(s) again one at a time",
                RuntimeWarning,
                stacklevel=2,
            )
        for key in suspects:
            _round(fn, items, [key], 1, threads, hooks, solo=True)


def _round(fn, items, queue, workers, threads, hooks, solo: bool = False) -> list:
    """Run the keys of ``queue`` (consumed) in one pool until done or the pool breaks;
    returns the keys that were running when it broke (``solo``: ``on_died`` instead)."""
    on_result, on_error, on_died = hooks
    ctx = multiprocessing.get_context("spawn")
    started = ctx.Value("i", 0)
    pool = ProcessPoolExecutor(
        workers, mp_context=ctx, initializer=_init_worker, initargs=(threads, started, os.getpid())
    )
    finished, broken = False, []
    running: dict = {}
    try:
        while queue or running:
            try:
                _top_up(pool, fn, items, queue, running, workers)
            except BrokenProcessPool:  # broke before we noticed: settle what ran
                done = set(running)
                if not running:  # no worker even started
                    broken.append(queue.pop(0))
            else:
                done, _ = wait(running, return_when=FIRST_COMPLETED)
            finished_now = []
            for fut in done:
                key = running.pop(fut)
                try:
                    finished_now.append((key, fut.result()))
                except BrokenProcessPool:
                    broken.append(key)
                except Exception as exc:
                    if on_error(key, exc):
                        queue.insert(0, key)
            if not broken:  # keep the workers busy while the driver handles the results
                with contextlib.suppress(BrokenProcessPool):  # settled on the next pass
                    _top_up(pool, fn, items, queue, running, workers)
            for key, value in finished_now:
                on_result(key, value)
            if broken:
                broken += running.values()
                running.clear()
                break
        finished = True
    finally:
        if not finished or broken:  # do not wait for running items
            for proc in list(getattr(pool, "_processes", {}).values()):
                proc.terminate()
        pool.shutdown(wait=finished and not broken, cancel_futures=True)
    if broken and started.value == 0:  # not the items' fault: none was ever run
        raise EvalError(NOT_STARTED)
    if solo and broken:
        on_died(broken[0])
        return []
    return sorted(broken)


def _top_up(pool, fn, items, queue, running, workers) -> None:
    """Submit the next keys of ``queue`` until ``workers`` items are running."""
    while queue and len(running) < workers:
        running[pool.submit(fn, *items[queue[0]])] = queue[0]
        queue.pop(0)
