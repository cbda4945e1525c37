"""The work of ``torchsar-eval run`` as plain typed functions: every dataset scored shard by
shard (optionally with a calibration split), the resumable result folder, the tables."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from torchsar_eval.calibrate import choose_bin, parse_target, split_indices
from torchsar_eval.commands.run.report import write_tables
from torchsar_eval.detectors import DetectorSpec, dry_run
from torchsar_eval.errors import EvalError
from torchsar_eval.output import file_slugs, result_dir, write_config
from torchsar_eval.plots import slug
from torchsar_eval.runner import Scoring, SkipBad
from torchsar_eval.shards import ShardJob, run_shards, shard_coco

__all__ = ["Calibration", "Execution", "RunPlan", "evaluate_dataset", "execute"]


@dataclass(frozen=True)
class Execution:
    """How a dataset's shards are run: batch and shard sizes, local processes or Ray, what
    happens to unreadable files and failing shards, and the progress bar."""

    batch_size: int = 16
    shard_size: int = 256
    workers: int = 1
    engine: str = "local"
    address: str | None = None
    skip_bad: bool = False
    progress: bool = True


@dataclass(frozen=True)
class Calibration:
    """Choose each detector's operating point on a hashed ``fraction`` of the images for
    ``target`` (``"fa=L"`` or ``"f1"``) and report on the disjoint rest."""

    target: str
    fraction: float = 0.3


@dataclass(frozen=True)
class RunPlan:
    """Everything a run does to each dataset (the validated command-line options)."""

    specs: list[DetectorSpec]
    scoring: Scoring
    preprocess: Callable | None = None
    despeckle: dict | None = None
    execution: Execution = Execution()
    calibration: Calibration | None = None
    window_units: str = "px"
    export_coco: bool = False
    seed: int = 0


def execute(plan: RunPlan, datasets: dict, out: Path, *, resume: bool = False):
    """Score every dataset into the result folder ``out`` (atomically, resumable); returns
    each dataset's run statistics and the names of the files written."""
    with result_dir(out, resume=resume, keep_interrupted=True) as tmp:
        check_resumable(tmp / "resume.json", fingerprint(plan, datasets))
        results, stats, windows = {}, {}, {}
        labels = file_slugs(datasets, slug)  # unique file names even for same-named folders
        for name, ds in datasets.items():
            specs = (
                plan.specs if plan.window_units == "px" else windows_in_pixels(name, ds, plan.specs)
            )
            windows[name] = {s.name: dict(s.params) for s in specs}
            results[name], stats[name] = evaluate_dataset(
                name, ds, specs, plan, tmp / "shards" / labels[name]
            )
            exporter = stats[name].pop("export")
            if exporter is not None:
                exporter.write(tmp / "coco", labels[name])
        files = write_tables(tmp, results, plan.scoring, stats, labels)
        write_config(tmp, "run", config(plan, datasets, windows, stats, out))
    return stats, files


def config(plan: RunPlan, datasets: dict, windows: dict, stats: dict, out: Path) -> dict:
    """The ``config.json`` record of a run."""
    ex, cal = plan.execution, plan.calibration
    return {
        "datasets": {n: getattr(d, "options", {}) for n, d in datasets.items()},
        "manifests": {n: d.manifest() for n, d in datasets.items() if hasattr(d, "manifest")},
        "detectors": {s.name: dict(s.params) for s in plan.specs},
        "window_units": plan.window_units,
        "detectors_in_pixels": windows,
        "despeckle": plan.despeckle,
        "scoring": plan.scoring.as_dict(),
        "workers": ex.workers,
        "shard_size": ex.shard_size,
        "throughput": stats,
        "calibration": None if cal is None else {"target": cal.target, "fraction": cal.fraction},
        "batch_size": ex.batch_size,
        "seed": plan.seed,
        "out": str(out),
    }


def windows_in_pixels(name: str, ds, specs: list) -> list:
    """Detectors with ``guard`` / ``train`` given in metres converted to pixels with the
    dataset's pixel spacing (the mean of its row and column spacing, read from item 0)."""
    spacing = ds[0]["meta"].get("pixel_spacing") if len(ds) else None
    if spacing is None:
        raise EvalError(f"--window-units m needs the pixel spacing of {name}: declare it with "
                        f"?spacing=METRES")  # fmt: skip
    step = (float(spacing[0]) + float(spacing[1])) / 2
    out = []
    for spec in specs:
        conv = {k: round(float(spec.params[k]) / step) for k in ("guard", "train")
                if k in spec.params}  # fmt: skip
        if conv.get("train", 1) < 1:
            raise EvalError(f"{spec.name}: train {spec.params['train']} m is less than one "
                            f"pixel of {name} ({step:g} m)")  # fmt: skip
        spec = spec.with_params(conv)
        dry_run(spec.fn, spec.params, f"detector {spec.name} on {name}")
        out.append(spec)
    return out


def fingerprint(plan: RunPlan, datasets: dict) -> dict:
    """Everything a saved shard depends on (a resumed run must match it exactly)."""
    cal = plan.calibration
    return json.loads(json.dumps({
        "datasets": {n: getattr(d, "options", {}) for n, d in datasets.items()},
        "detectors": {s.name: dict(s.params) for s in plan.specs},
        "despeckle": plan.despeckle,
        "scoring": plan.scoring.as_dict(), "shard_size": plan.execution.shard_size,
        "calibration": None if cal is None else [cal.target, cal.fraction],
        "export_coco": plan.export_coco,  # shards saved without their COCO part cannot serve
    }, default=str))  # fmt: skip


def check_resumable(path: Path, expected: dict) -> None:
    """Record the run's fingerprint, or check it against the one of the run being resumed."""
    if path.exists():
        if json.loads(path.read_text()) != expected:
            raise EvalError(f"--resume: the options differ from those of the interrupted run "
                            f"(see {path.name} in its folder); rerun without --resume")  # fmt: skip
        return
    path.write_text(json.dumps(expected, indent=2) + "\n")


def evaluate_dataset(name: str, ds, specs: list[DetectorSpec], plan: RunPlan, state: Path):
    """Score one dataset shard by shard; with a calibration each detector's operating point
    is chosen on the calibration split and the results are the disjoint test split's.
    Returns the merged results and the dataset's run statistics (wall time, shards)."""
    t0 = time.perf_counter()
    ex, cal = plan.execution, plan.calibration
    indices = list(range(len(ds)))
    if ex.skip_bad:
        ds = SkipBad(ds)

    def shards(idx: list[int], folder: Path, export: bool = False):
        job = ShardJob(name, ds, idx, specs, plan.scoring, ex.batch_size, plan.preprocess,
                       ex.shard_size, export_coco=export)  # fmt: skip
        return run_shards(job, folder, workers=ex.workers, engine=ex.engine,
                          address=ex.address, skip_bad=ex.skip_bad,
                          progress=ex.progress)  # fmt: skip

    chosen = None
    if cal is not None:
        target = parse_target(cal.target)
        calib, indices = split_indices(len(ds), name, cal.fraction)
        if not calib or not indices:
            raise EvalError(f"dataset {name} has {len(ds)} images: too few for a calibration "
                            f"split of {cal.fraction:g}")  # fmt: skip
        tuned, _ = shards(calib, state / "calibration")
        chosen = [choose_bin(r.objects, target) for r in tuned]
    results, counts = shards(indices, state / "test", plan.export_coco)
    exporter = shard_coco(state / "test", name) if plan.export_coco else None
    for r, b in zip(results, chosen or [], strict=False):
        r.op_bin = b
    wall = time.perf_counter() - t0
    bad = results[0].skipped if results else []
    stats = {"images": len(indices), "wall_s": wall, **counts, "export": exporter,
             "skipped_items": [{"file": f, "error": e} for f, e in bad],
             "images_per_s": len(indices) / wall if wall > 0 else float("nan")}  # fmt: skip
    return results, stats
