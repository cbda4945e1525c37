"""Benchmark report: evaluator throughput, the eight default detectors with full scoring.

A seeded store of simulated 128x128 chips (``sim-chips``, written once into a temporary
folder as ``torchsar-eval make-dataset`` writes it) is evaluated by
:func:`torchsar_eval.evaluate` with the detectors ``ca, two_parameter, go, so, os, vi, ac,
region`` and the default scoring (discrimination, matching, AP records, FROC, SCR, error
types, per-image rows, 200 bootstrap replicates), once per worker count. Each row gives
the wall time and images per second of the whole run, and from its timing table the
split of the per-image cost: detector milliseconds and scoring (object stage)
milliseconds summed over the eight detectors, and the scoring cost per chip and detector.
The two parts are measured inside the workers, so with several workers they add up to
more than the wall time per image. One small evaluation first warms the imports and the
compiled kernels' caches; each worker process still starts, imports and loads its kernels
within the timed run, as in any run.

Run: ``python scripts/benchmark.py --topic throughput [--n 256] [--workers 1 2]
[--device cpu]`` (about a minute at the default size on two cores).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

DETECTORS = ("ca", "two_parameter", "go", "so", "os", "vi", "ac", "region")
DEFAULT_N = 256
COLUMNS = (
    "workers",
    "images",
    "wall_s",
    "images_per_s",
    "detector_ms_per_image",
    "scoring_ms_per_image",
    "scoring_ms_per_chip_and_detector",
)


def make_store(root: Path, n: int, seed: int = 0) -> str:
    """Write ``n`` seeded simulated chips into a store under ``root``; its dataset spec."""
    from torchsar_eval.datasets import make_dataset
    from torchsar_eval.store import write_store

    ds = make_dataset("sim-chips", n=n, seed=seed)
    out = write_store((ds[i] for i in range(n)), n, root / "store")
    return f"store:{out}"


def measure(spec: str, workers: int, device: str | None = None) -> dict:
    """One evaluation of the store ``spec`` with ``workers`` worker processes: a row of
    :data:`COLUMNS`."""
    from torchsar_eval import Execution, evaluate

    ex = Execution(workers=workers, device=device, progress=False)
    t0 = time.perf_counter()
    res = evaluate(spec, list(DETECTORS), execution=ex)
    wall = time.perf_counter() - t0
    timing = res.timing
    images = int(timing["images"].iloc[0])
    scoring = float(timing["object_ms_per_image"].sum())
    return {
        "workers": workers,
        "images": images,
        "wall_s": wall,
        "images_per_s": images / wall,
        "detector_ms_per_image": float(timing["ms_per_image"].sum()),
        "scoring_ms_per_image": scoring,
        "scoring_ms_per_chip_and_detector": scoring / len(timing),
    }


def report(
    n: int = DEFAULT_N, workers: tuple[int, ...] = (1, 2), device: str | None = None, seed: int = 0
) -> list[dict]:
    """Rows of :data:`COLUMNS`, one per worker count, on one store of ``n`` chips."""
    from torchsar_eval import Execution, evaluate

    with tempfile.TemporaryDirectory(prefix="torchsar-throughput-") as tmp:
        spec = make_store(Path(tmp), n, seed)
        warm = Execution(device=device, progress=False)  # imports, compiled kernels' caches
        evaluate(spec, list(DETECTORS), execution=warm, n=min(n, 2))
        return [measure(spec, w, device) for w in workers]


def format_rows(rows: list[dict]) -> str:
    """The rows as an aligned text table."""
    lines = [
        f"{'workers':>7s} {'images':>6s} {'wall s':>8s} {'images/s':>9s} "
        f"{'detector ms/img':>15s} {'scoring ms/img':>14s} {'scoring ms/chip/det':>19s}"
    ]
    for r in rows:
        lines.append(
            f"{r['workers']:7d} {r['images']:6d} {r['wall_s']:8.2f} "
            f"{r['images_per_s']:9.2f} {r['detector_ms_per_image']:15.2f} "
            f"{r['scoring_ms_per_image']:14.2f} "
            f"{r['scoring_ms_per_chip_and_detector']:19.3f}"
        )
    return "\n".join(lines)
