"""Speed ratios of torchsar against reference implementations, measured in the same run.

Every file in ``scripts/benchmarks/`` defines ``cases() -> [(name, ours, reference), ...]``,
or is a report that measures one thing at several settings and defines ``report(n, workers,
device) -> [row, ...]`` and ``format_rows(rows) -> str`` instead (``throughput``: images per
second of the evaluator; run it by ``--topic``, with ``--n``, ``--workers`` and
``--device``). Each pair is timed on 1 thread, A/B interleaved (one warm-up each, then
``--repeat`` rounds of ours, reference, ours, ...), so both see the same machine load; a
call shorter than 5 ms is repeated within its round until the round lasts about 5 ms and
timed per call, on both sides alike, so short calls are timed as a loop over many images
runs them and not by a timer's resolution and cold caches. Each round starts with one
untimed call of the same function (a lead-in; ``--cold`` leaves it out), so each side is
timed in its steady state and not in the switch from the other side's code: on the 2-core
VMs here the first ~10 ms of vectorised work after a different workload (or an idle
pause) runs up to 3x slower, which doubled a 9 ms kernel timed right after a 380 ms
scalar reference. The medians of wall and CPU
(thread) time are printed with the ratio ``reference / ours`` of the
medians (> 1 means torchsar is faster). CPU time is the fairer figure on a busy host. A
reference may be an older implementation of ours (e.g. ``region`` and ``cfar_family`` time
the compiled numba path against the numpy/torch path it replaces, see :mod:`torchsar._jit`).

Usage: ``python scripts/benchmark.py [--topic FILE_STEM] [--only SUBSTRING] [--repeat N]
[--csv PATH] [--n N] [--workers W ...] [--device DEVICE] [--cold]``
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
import torch

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))


ROUND_S = 0.005  # a call shorter than this is repeated within a round to about this long


def _timed(fn: Callable[[], object], calls: int = 1) -> tuple[float, float]:
    """Wall and CPU seconds per call of ``calls`` calls of ``fn`` in a row."""
    t0, c0 = time.perf_counter(), time.thread_time()
    for _ in range(calls):
        fn()
    return (time.perf_counter() - t0) / calls, (time.thread_time() - c0) / calls


def calls_per_round(seconds: float) -> int:
    """How many calls of a function that took ``seconds`` make a round of about
    :data:`ROUND_S` (at least one, at most 1000)."""
    return max(1, min(1000, int(ROUND_S / max(seconds, 1e-9))))


def interleaved(
    ours: Callable[[], object], ref: Callable[[], object], repeat: int, lead_in: bool = True
) -> tuple[tuple[float, float], tuple[float, float]]:
    """Median (wall, CPU) seconds per call of ``ours`` and of ``ref``, timed alternately in
    ``repeat`` rounds each after two warm-up runs of each (a round of a short call repeats
    it, :func:`calls_per_round`); ``lead_in``: each round starts with one untimed call."""
    ours(), ref()  # the first call may compile or load a kernel: not a measure of a call
    calls = {"ours": calls_per_round(_timed(ours)[0]), "ref": calls_per_round(_timed(ref)[0])}
    runs: dict[str, list[tuple[float, float]]] = {"ours": [], "ref": []}
    for _ in range(repeat):
        for key, fn in (("ours", ours), ("ref", ref)):
            if lead_in:
                fn()
            runs[key].append(_timed(fn, calls[key]))

    def median(key: str) -> tuple[float, float]:
        return (
            statistics.median(t[0] for t in runs[key]),
            statistics.median(t[1] for t in runs[key]),
        )

    return median("ours"), median("ref")


def load_topic(path: Path):
    """The benchmark module ``path`` (a file of ``scripts/benchmarks/``)."""
    spec = importlib.util.spec_from_file_location(f"bench_{path.stem}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def load_cases(only: str | None, topic: str | None = None) -> list[tuple[str, Callable, Callable]]:
    """The A/B cases of every topic (or of ``topic``) whose name contains ``only``; report
    topics (without ``cases``) are left out."""
    out = []
    for path in sorted((HERE / "benchmarks").glob(f"{topic or '*'}.py")):
        mod = load_topic(path)
        if hasattr(mod, "cases"):
            out += [c for c in mod.cases() if only is None or only in c[0]]
    return out


def run_report(
    mod, n: int | None, workers: list[int] | None, device: str | None, csv: Path | None
) -> int:
    """Run a report topic (a module with ``report``), print its table, optionally write it
    as CSV."""
    kwargs = {"device": device}
    if n is not None:
        kwargs["n"] = n
    if workers:
        kwargs["workers"] = tuple(workers)
    rows = mod.report(**kwargs)
    print(mod.format_rows(rows), flush=True)
    if csv:
        import pandas as pd

        pd.DataFrame(rows).to_csv(csv, index=False)
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--topic", help="run only scripts/benchmarks/<TOPIC>.py (e.g. speckle)")
    p.add_argument("--only", help="run cases whose name contains this substring")
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--csv", type=Path, help="also write the table as CSV")
    p.add_argument("--n", type=int, help="images of a report topic (throughput: default 256)")
    p.add_argument(
        "--workers",
        type=int,
        nargs="+",
        help="worker counts of a report topic (throughput: default 1 2)",
    )
    p.add_argument("--device", help="where a report topic's detectors run (cpu, cuda, ...)")
    p.add_argument(
        "--cold",
        action="store_true",
        help="no untimed lead-in call before each round (time each side right after the other's)",
    )
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    path = HERE / "benchmarks" / f"{args.topic}.py"
    if args.topic and path.is_file() and hasattr(mod := load_topic(path), "report"):
        return run_report(mod, args.n, args.workers, args.device, args.csv)
    rows = []
    for name, ours, ref in load_cases(args.only, args.topic):
        (t_ours, c_ours), (t_ref, c_ref) = interleaved(ours, ref, args.repeat, not args.cold)
        rows.append(
            (
                name,
                t_ours * 1e3,
                t_ref * 1e3,
                c_ours * 1e3,
                c_ref * 1e3,
                t_ref / t_ours,
                c_ref / max(c_ours, 1e-9),
            )
        )
        print(
            f"{name:<70s} ours {t_ours * 1e3:9.2f} ms  ref {t_ref * 1e3:9.2f} ms  "
            f"ratio {t_ref / t_ours:6.2f}x  (cpu {c_ours * 1e3:9.2f} / {c_ref * 1e3:9.2f} ms, "
            f"ratio {c_ref / max(c_ours, 1e-9):6.2f}x)",
            flush=True,
        )
    if args.csv:
        import pandas as pd

        pd.DataFrame(
            rows,
            columns=[
                "case",
                "ours_ms",
                "reference_ms",
                "ours_cpu_ms",
                "reference_cpu_ms",
                "speedup",
                "cpu_speedup",
            ],
        ).to_csv(args.csv, index=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
