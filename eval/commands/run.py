"""``torchsar-eval run``: evaluate detectors on datasets; summary, ROC tables and plots."""

from __future__ import annotations

import argparse
import csv
import json
import time
from pathlib import Path

import pandas as pd

from eval.calibrate import choose_bin, parse_target, split_indices
from eval.coco import CocoExport
from eval.datasets import DATASETS, make_dataset
from eval.detectors import DETECTORS, dry_run
from eval.errors import EvalError
from eval.glossary import glossary
from eval.options import check_run_args
from eval.output import default_out, file_slugs, result_dir, write_config
from eval.plots import plot_roc, slug
from eval.runner import DEFAULT_MATCH, DEFAULT_RULES, Scoring, SkipBad
from eval.shards import ShardJob, run_shards, shard_rows
from eval.tables import (
    PER_IMAGE_COLUMNS,
    breakdown_table,
    froc_table,
    headline_table,
    markdown,
    pixel_roc_table,
    pr_table,
    summary_table,
    timing_table,
)
from torchsar._checks import TorchSARError
from torchsar.metrics import Matching
from torchsar.objects import ObjectRules
from torchsar.speckle import FILTERS

DEFAULT_DATASETS = ["sim-chips", "sim-scenes"]

SUMMARY_SHOWN = [
    "dataset",
    "detector",
    "images",
    "pd_pixel",
    "pfa_pixel",
    "tp",
    "fp",
    "fn",
    "precision",
    "recall",
    "f1",
    "ap50",
    "pd_at_1_fa_per_image",
    "false_alarms_per_image",
    "mean_iou",
    "ms_per_image",
]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "run",
        help="evaluate detectors on datasets (the default: every detector on simulated data)",
        description="Score detectors against ground-truth masks; write summary.csv, roc.csv, "
        "summary.md, roc_<dataset>.png and config.json.",
    )
    p.add_argument(
        "--dataset",
        action="append",
        metavar="NAME",
        help=f"dataset (repeatable): {', '.join(DATASETS)}; "
        f"default: {' and '.join(DEFAULT_DATASETS)}",
    )
    p.add_argument(
        "--detectors",
        default=None,
        help=f"comma-separated detectors (default: all): {','.join(DETECTORS)}",
    )
    p.add_argument("--n", type=int, default=None, help="images per dataset (default: per dataset)")
    p.add_argument("--batch-size", type=int, default=16)
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated datasets")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: results/run-*)")
    p.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="DET.KEY=VALUE",
        help="detector parameter override, e.g. ca.guard=3 (repeatable)",
    )
    p.add_argument(
        "--despeckle",
        choices=sorted(FILTERS),
        default=None,
        help="speckle filter applied before every detector (default: none)",
    )
    p.add_argument(
        "--despeckle-param",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="speckle filter option, e.g. window=7 or looks=4 (repeatable)",
    )
    add_scoring_options(p)
    p.add_argument(
        "--export-coco",
        action="store_true",
        help="also write coco/<dataset>__gt.json and coco/<dataset>__<detector>.json (COCO "
        "ground truth and results with scores) for re-scoring with pycocotools",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=1,
        help="worker processes (each gets cores // workers torch threads); default 1",
    )
    p.add_argument(
        "--shard-size",
        type=int,
        default=256,
        help="images per shard, the unit of work and of resume (default 256)",
    )
    p.add_argument(
        "--window-units",
        choices=["px", "m"],
        default="px",
        help="units of the detectors' guard and train options: pixels, or metres converted "
        "per dataset with its pixel spacing (recorded in config.json)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the interrupted run in --out: its saved shards are kept, the rest is "
        "scored (the options must be the same)",
    )
    p.add_argument(
        "--engine",
        choices=["local", "ray"],
        default="local",
        help="run shards locally (--workers processes) or as Ray tasks (pip install "
        "'torchsar[ray]')",
    )
    p.add_argument("--address", default=None, help="Ray cluster address (default: local Ray)")
    p.add_argument(
        "--skip-bad",
        action="store_true",
        help="skip unreadable files and failing shards, counting and naming them in the "
        "summary (default: stop at the first, naming it, and write no tables)",
    )
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")
    p.set_defaults(func=run)


def add_scoring_options(p: argparse.ArgumentParser) -> None:
    """The discrimination and matching options shared by every detector of a run."""
    g = p.add_argument_group("objects and matching (the same for every detector)")
    g.add_argument(
        "--closing",
        type=int,
        default=DEFAULT_RULES.closing,
        help=f"closing radius in px before labelling (default {DEFAULT_RULES.closing})",
    )
    g.add_argument(
        "--min-area",
        type=float,
        default=DEFAULT_RULES.min_area,
        help=f"smallest object, in --area-units (default {DEFAULT_RULES.min_area:g})",
    )
    g.add_argument(
        "--max-area",
        type=float,
        default=DEFAULT_RULES.max_area,
        help="largest object, in --area-units (default: no limit)",
    )
    g.add_argument("--area-units", choices=["px", "m2"], default="px")
    g.add_argument(
        "--floor",
        type=float,
        default=1.0,
        help="objects are components of score > FLOOR (1 = design mask; lower "
        "extends the curves past the design point)",
    )
    g.add_argument(
        "--match",
        choices=["centroid", "mask", "box"],
        default=DEFAULT_MATCH.kind,
        help=f"matching rule of the operating point and FROC (default "
        f"{DEFAULT_MATCH.kind}); AP always uses IoU",
    )
    g.add_argument("--iou", type=float, default=0.5, help="IoU threshold of --match mask|box")
    g.add_argument(
        "--bootstrap",
        type=int,
        default=100,
        help="bootstrap replicates for the intervals (0: none)",
    )
    g.add_argument(
        "--calibrate-on",
        metavar="TARGET",
        default=None,
        help="choose each detector's score threshold on a calibration split for "
        "TARGET ('fa=1': at most 1 false alarm per image; 'f1': best F1) and "
        "report on the disjoint rest",
    )
    g.add_argument("--calibration-fraction", type=float, default=0.3,
                   help="share of each dataset's images in the calibration split")  # fmt: skip


def scoring_from(args: argparse.Namespace) -> Scoring:
    """The run's :class:`Scoring` from the parsed options (validated here, before any work)."""
    if args.bootstrap < 0:
        raise EvalError(f"--bootstrap must be >= 0, got {args.bootstrap}")
    try:
        rules = ObjectRules(
            closing=args.closing, min_area=args.min_area, max_area=args.max_area,
            units=args.area_units, floor=args.floor,
        )  # fmt: skip
        matching = Matching(kind=args.match, iou=args.iou)
    except TorchSARError as exc:
        raise EvalError(f"bad object/matching option: {exc}") from exc
    return Scoring(rules, matching, args.bootstrap, args.seed)


def run(args: argparse.Namespace) -> int:
    specs, preprocess, despeckle_opts = check_run_args(args)
    if args.workers < 1 or args.shard_size < 1:
        raise EvalError("--workers and --shard-size must be >= 1")
    if args.export_coco and (args.workers > 1 or args.engine != "local"):
        raise EvalError("--export-coco collects detections in this process: use --workers 1")
    datasets = {
        name: make_dataset(name, n=args.n, seed=args.seed)
        for name in (args.dataset or DEFAULT_DATASETS)
    }
    scoring = scoring_from(args)
    out = args.out or default_out("run")
    with result_dir(out, resume=args.resume, keep_interrupted=True) as tmp:
        check_resumable(tmp / "resume.json", fingerprint(args, datasets, specs, scoring))
        results, stats, windows = {}, {}, {}
        labels = file_slugs(datasets, slug)  # unique file names even for same-named folders
        for name, ds in datasets.items():
            ds_specs = specs if args.window_units == "px" else windows_in_pixels(name, ds, specs)
            windows[name] = {s.name: dict(s.params) for s in ds_specs}
            results[name], stats[name] = evaluate_dataset(
                name, ds, ds_specs, args, scoring, preprocess, tmp / "shards" / labels[name]
            )
            exporter = stats[name].pop("export")
            if exporter is not None:
                exporter.write(tmp / "coco", labels[name])
        files = write_tables(tmp, results, scoring, stats, labels)
        write_config(
            tmp,
            "run",
            {
                "datasets": {n: getattr(d, "options", {}) for n, d in datasets.items()},
                "manifests": {
                    n: d.manifest() for n, d in datasets.items() if hasattr(d, "manifest")
                },
                "detectors": {s.name: dict(s.params) for s in specs},
                "window_units": args.window_units,
                "detectors_in_pixels": windows,
                "despeckle": None
                if args.despeckle is None
                else {"filter": args.despeckle, **despeckle_opts},
                "scoring": scoring.as_dict(),
                "workers": args.workers,
                "shard_size": args.shard_size,
                "throughput": stats,
                "calibration": None
                if args.calibrate_on is None
                else {"target": args.calibrate_on, "fraction": args.calibration_fraction},
                "batch_size": args.batch_size,
                "seed": args.seed,
                "out": str(out),
            },
        )
    summary = pd.read_csv(out / "summary.csv").merge(
        pd.read_csv(out / "timing.csv"), on=["dataset", "detector", "images"]
    )
    print(summary[SUMMARY_SHOWN].to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    for name, st in stats.items():
        print(
            f"{name}: {st['images']} images in {st['wall_s']:.1f} s "
            f"({st['images_per_s']:.3g} images/s), shards {st['shards']} "
            f"(done {st['done']}, resumed {st['skipped']}, failed {len(st['failed'])})"
        )
        for f in st["failed"]:
            print(f"  FAILED shard {f['shard']}: {f['error']}")
        for b in st["skipped_items"]:
            print(f"  skipped unreadable {b['file']}")
    print(f"\nwrote {out}/: " + " ".join([*files, "config.json"]))
    return 0


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


def fingerprint(args, datasets: dict, specs: list, scoring: Scoring) -> dict:
    """Everything a saved shard depends on (a resumed run must match it exactly)."""
    return json.loads(json.dumps({
        "datasets": {n: getattr(d, "options", {}) for n, d in datasets.items()},
        "detectors": {s.name: dict(s.params) for s in specs},
        "despeckle": [args.despeckle, sorted(args.despeckle_param)],
        "scoring": scoring.as_dict(), "shard_size": args.shard_size,
        "calibration": [args.calibrate_on, args.calibration_fraction],
    }, default=str))  # fmt: skip


def check_resumable(path: Path, expected: dict) -> None:
    """Record the run's fingerprint, or check it against the one of the run being resumed."""
    if path.exists():
        if json.loads(path.read_text()) != expected:
            raise EvalError(f"--resume: the options differ from those of the interrupted run "
                            f"(see {path.name} in its folder); rerun without --resume")  # fmt: skip
        return
    path.write_text(json.dumps(expected, indent=2) + "\n")


def evaluate_dataset(name, ds, specs, args, scoring, preprocess, state: Path):
    """Score one dataset shard by shard; with ``--calibrate-on`` each detector's operating
    point is chosen on the calibration split and the results are the disjoint test split's.
    Returns the merged results and the dataset's run statistics (wall time, shards)."""
    t0 = time.perf_counter()
    indices = list(range(len(ds)))
    if args.skip_bad:
        ds = SkipBad(ds)

    def shards(idx: list[int], folder: Path, on_batch=None):
        job = ShardJob(name, ds, idx, specs, scoring, args.batch_size, preprocess,
                       args.shard_size)  # fmt: skip
        return run_shards(job, folder, workers=args.workers, engine=args.engine,
                          address=args.address, skip_bad=args.skip_bad,
                          progress=not args.no_progress, on_batch=on_batch)  # fmt: skip

    chosen = None
    if args.calibrate_on is not None:
        target = parse_target(args.calibrate_on)
        cal, indices = split_indices(len(ds), name, args.calibration_fraction)
        if not cal or not indices:
            raise EvalError(f"dataset {name} has {len(ds)} images: too few for a calibration "
                            f"split of {args.calibration_fraction:g}")  # fmt: skip
        tuned, _ = shards(cal, state / "calibration")
        chosen = [choose_bin(r.objects, target) for r in tuned]
    exporter = CocoExport(name) if args.export_coco else None
    results, counts = shards(indices, state / "test", exporter.add if exporter else None)
    for r, b in zip(results, chosen or [], strict=False):
        r.op_bin = b
    wall = time.perf_counter() - t0
    bad = results[0].skipped if results else []
    stats = {"images": len(indices), "wall_s": wall, **counts, "export": exporter,
             "skipped_items": [{"file": f, "error": e} for f, e in bad],
             "images_per_s": len(indices) / wall if wall > 0 else float("nan")}  # fmt: skip
    return results, stats


def write_per_image(path: Path, folders: dict[str, Path]) -> None:
    """``per_image.csv`` streamed from the saved shards (memory independent of the dataset
    size): one row per image and detector, datasets and shards in order."""
    with open(path, "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(PER_IMAGE_COLUMNS)
        for name, folder in folders.items():
            for det, rows in shard_rows(folder):
                out.writerows([name, det, *row] for row in rows)


def write_tables(
    tmp: Path, results: dict, scoring: Scoring, stats: dict, labels: dict[str, str]
) -> list[str]:
    """Every table and plot of a run into ``tmp``; returns the file names."""
    summary = summary_table(results)
    tables = {
        "summary.csv": summary,
        "roc.csv": froc_table(results),
        "pr.csv": pr_table(results),
        "roc_pixel.csv": pixel_roc_table(results),
        "breakdown.csv": breakdown_table(results),
        "timing.csv": timing_table(results),
    }
    for fname, df in tables.items():
        df.to_csv(tmp / fname, index=False)
    write_per_image(
        tmp / "per_image.csv", {n: tmp / "shards" / labels[n] / "test" for n in results}
    )
    text = glossary(summary, scoring) + "\n" + markdown(headline_table(summary))
    text += "\nEvery column, for every detector, is in `summary.csv`.\n"
    text += "\n## Timing\n\n" + markdown(tables["timing.csv"])
    text += "".join(
        f"\n- {name}: {st['images']} images in {st['wall_s']:.1f} s "
        f"({st['images_per_s']:.3g} images/s); shards {st['shards']}: done {st['done']}, "
        f"resumed {st['skipped']}, failed {len(st['failed'])}"
        + "".join(f"\n  - FAILED shard {f['shard']}: {f['error']}" for f in st["failed"])
        + (
            f"\n  - skipped {len(st['skipped_items'])} unreadable file(s)"
            if st["skipped_items"]
            else ""
        )
        + "".join(f"\n    - {b['file']}: {b['error']}" for b in st["skipped_items"])
        for name, st in stats.items()
    )
    (tmp / "summary.md").write_text(text)
    files = [*tables, "per_image.csv", "summary.md"]
    for name in results:
        sel = {k: df[df.dataset == name] for k, df in tables.items()}
        files += plot_roc(
            sel["roc_pixel.csv"], sel["roc.csv"], sel["pr.csv"], sel["summary.csv"],
            tmp / f"roc_{labels[name]}.png", name,
        )  # fmt: skip
    return files
