"""Speed ratios of torchsar against reference implementations, measured in the same run.

Every file in ``scripts/benchmarks/`` defines ``cases() -> [(name, ours, reference), ...]``.
Each callable is timed on 1 thread (best of ``--repeat`` runs after a warm-up, wall and CPU
time; CPU time is the fairer figure on a busy host) and the ratio ``reference / ours`` of
wall times is printed (> 1 means torchsar is faster).

Usage: ``python scripts/benchmark.py [--topic FILE_STEM] [--only SUBSTRING] [--repeat N]
[--csv PATH]``
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
import torch

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))


def best_time(fn: Callable[[], object], repeat: int) -> tuple[float, float]:
    """Best wall and best CPU time of ``repeat`` runs after one warm-up run."""
    fn()
    wall, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return min(wall), min(cpu)


def load_cases(only: str | None, topic: str | None = None) -> list[tuple[str, Callable, Callable]]:
    out = []
    for path in sorted((HERE / "benchmarks").glob(f"{topic or '*'}.py")):
        spec = importlib.util.spec_from_file_location(f"bench_{path.stem}", path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        out += [c for c in mod.cases() if only is None or only in c[0]]
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--topic", help="run only scripts/benchmarks/<TOPIC>.py (e.g. speckle)")
    p.add_argument("--only", help="run cases whose name contains this substring")
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--csv", type=Path, help="also write the table as CSV")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    rows = []
    for name, ours, ref in load_cases(args.only, args.topic):
        (t_ours, c_ours), (t_ref, c_ref) = best_time(ours, args.repeat), best_time(ref, args.repeat)
        rows.append((name, t_ours * 1e3, t_ref * 1e3, c_ours * 1e3, c_ref * 1e3, t_ref / t_ours))
        print(
            f"{name:<70s} ours {t_ours * 1e3:9.2f} ms  ref {t_ref * 1e3:9.2f} ms  "
            f"ratio {t_ref / t_ours:6.2f}x  (cpu ratio {c_ref / max(c_ours, 1e-9):6.2f}x)",
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
            ],
        ).to_csv(args.csv, index=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
