"""``torchsar-eval run``: evaluate detectors on datasets; summary, ROC tables and plots.

The command-line edge of :func:`torchsar_eval.evaluate`: options are parsed and validated
here (:mod:`torchsar_eval.commands.run.options`), turned into the typed settings of the
Python API and handed to it; this module prints the summary. The parser imports nothing
heavy (its names and defaults come from :mod:`torchsar_eval.choices`).
"""

from __future__ import annotations

import argparse
import importlib
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

from torchsar_eval import choices
from torchsar_eval.errors import EvalError

if TYPE_CHECKING:
    from torchsar_eval.api import Results

__all__ = ["DEFAULT_DATASETS", "DEFAULT_MATCH", "DEFAULT_RULES", "add_parser", "run"]

DEFAULT_DATASETS = ["sim-chips", "sim-scenes"]

_LAZY = {"DEFAULT_MATCH": "torchsar_eval.result", "DEFAULT_RULES": "torchsar_eval.result"}


def __getattr__(name: str) -> object:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "run",
        help="evaluate detectors on datasets (the default: every detector on simulated data)",
        description="Score detectors against ground-truth masks; write summary.csv, roc.csv, "
        "summary.md, roc_<dataset>.png, report.html, gallery/ and config.json.",
    )
    p.add_argument(
        "--dataset",
        action="append",
        metavar="NAME",
        help=f"dataset (repeatable): {', '.join(choices.DATASET_SCHEMES)}; "
        f"default: {' and '.join(DEFAULT_DATASETS)}",
    )
    p.add_argument(
        "--detectors",
        default=None,
        metavar="LIST",
        help="comma-separated detectors: built-in or registered names "
        f"({', '.join(choices.detector_names())}), import paths package.module:name, or "
        "NAME=REFERENCE to name a row (default: every built-in)",
    )
    p.add_argument(
        "--predictions",
        action="append",
        default=[],
        metavar="NAME=FILE",
        help="score saved predictions as detector NAME (repeatable): COCO results .json "
        "(bbox and/or segmentation, score), points .csv (image,row,col,score[,length_m]) "
        "or a folder of per-image masks; needs one --dataset",
    )
    p.add_argument(
        "--device",
        default=None,
        help="where detectors run: cpu, cuda, cuda:N (batches move there; scoring stays on "
        "the CPU; default: cpu)",
    )
    p.add_argument(
        "--n",
        type=int,
        default=None,
        help="images per dataset without its own n= option (sim-scenes?n=16); "
        "default: sim-chips 64, sim-scenes 4, files all",
    )
    p.add_argument("--batch-size", type=int, default=16, help="images per detector call")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated datasets")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: results/run-*)")
    p.add_argument(
        "--rank-by",
        default=choices.DEFAULT_RANK,
        metavar="METRIC",
        help="metric that ranks the leaderboards of report.html: "
        f"{', '.join(choices.RANK_METRICS)} (default {choices.DEFAULT_RANK})",
    )
    p.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="[DET.]KEY=VALUE",
        help="detector parameter override, e.g. ca.guard=3; KEY=VALUE (or *.KEY=VALUE) sets "
        "it on every detector that has it, e.g. pfa=1e-6; a detector's own wins (repeatable)",
    )
    p.add_argument(
        "--despeckle",
        choices=sorted(choices.SPECKLE_FILTERS),
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
        "--overlay",
        metavar="N|NAMES",
        default=None,
        help="draw whole images with every detector's detections over the ground truth "
        "(overlays/<dataset>/<detector>/<image>.png, and in the report): the first N images "
        "of the reported split, or the images named (comma-separated names, file names or "
        "stems)",
    )
    p.add_argument(
        "--figures",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="draw the curves, the gallery and report.html (default; --no-figures writes the "
        "tables and summaries only, and `torchsar-eval report RUN` builds the page later; "
        "TORCHSAR_EVAL_FIGURES=0 makes --no-figures the default)",
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
        "--discard",
        action="store_true",
        help="delete the saved work an interrupted run of --out left, and start over "
        "(without this or --resume, such a run is refused so its work is not lost)",
    )
    p.add_argument(
        "--engine",
        choices=["local", "ray"],
        default="local",
        help="run shards locally (--workers processes) or as Ray tasks (needs Ray; "
        "torchsar itself is shipped to the workers)",
    )
    p.add_argument("--address", default=None, help="Ray cluster address (default: local Ray)")
    p.add_argument(
        "--skip-bad",
        action="store_true",
        help="skip the images that cannot be read or that a detector fails on, and shards "
        "whose worker died twice, naming each in the summary (default: stop at the first, "
        "naming it, and write no tables)",
    )
    p.add_argument(
        "--max-bad",
        type=float,
        default=None,
        metavar="SHARE",
        help="with --skip-bad: the largest share (0-1) of a dataset's images that may be "
        "skipped before the run fails (default: any share short of all)",
    )
    p.add_argument(
        "--no-overlap",
        action="store_true",
        help="score each batch before detecting on the next (default: a worker runs the "
        "detectors on its next batch while it scores this one; one more batch in memory)",
    )
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")
    p.set_defaults(func=run, claims_out=True)


def add_scoring_options(p: argparse.ArgumentParser) -> None:
    """The discrimination and matching options shared by every detector of a run."""
    g = p.add_argument_group("objects and matching (the same for every detector)")
    g.add_argument(
        "--closing",
        type=int,
        default=choices.DEFAULT_CLOSING,
        help="closing radius in px before labelling",
    )
    g.add_argument(
        "--min-area",
        type=float,
        default=choices.DEFAULT_MIN_AREA,
        help="smallest object, in --area-units",
    )
    g.add_argument(
        "--max-area",
        type=float,
        default=choices.DEFAULT_MAX_AREA,
        help="largest object, in --area-units (default: no limit)",
    )
    g.add_argument(
        "--area-units",
        choices=["px", "m2"],
        default="px",
        help="units of --min-area and --max-area: pixels, or square metres with the pixel spacing",
    )
    g.add_argument(
        "--floor",
        type=float,
        default=1.0,
        help="objects are components of the pixels over FLOOR x each detector's design "
        "threshold (1 = its design mask; lower extends the curves past the design point)",
    )
    g.add_argument(
        "--match",
        choices=["centroid", "mask", "box", "distance"],
        default=choices.DEFAULT_MATCH_KIND,
        help="matching rule of the operating point and FROC; AP uses IoU, or the distance "
        "rule with --match distance",
    )
    g.add_argument("--iou", type=float, default=0.5, help="IoU threshold of --match mask|box")
    g.add_argument(
        "--class-agnostic",
        action="store_true",
        help="match every detection to every target whatever their classes (default: "
        "detections that carry classes match targets of their class, AP the mean over "
        "classes, as COCO)",
    )
    g.add_argument(
        "--max-distance",
        default=None,
        metavar="D",
        help="--match distance: the tolerance, e.g. 200m (with the pixel spacing) or 20px",
    )
    g.add_argument(
        "--assign",
        choices=["optimal", "greedy"],
        default="optimal",
        help="--match distance at the operating point: optimal assignment (xView3-SAR) or "
        "greedy by score (default optimal; AP and FROC are always greedy)",
    )
    g.add_argument(
        "--coco-compatible",
        action="store_true",
        help="also report pycocotools' 12 COCOeval stats exactly (per category, 100 "
        "detections per image and category, COCO area ranges) in coco.csv",
    )
    g.add_argument(
        "--instances",
        choices=["auto", "discriminate"],
        default="auto",
        help="auto: score each detector's own instances when it returns them (region "
        "labels, boxes, masks); discriminate: every detector's statistic through the same "
        "discrimination stage (default auto)",
    )
    g.add_argument(
        "--bootstrap",
        type=int,
        default=200,
        help="bootstrap replicates for the intervals (0: none; default 200: the interval "
        "width is known to about 5 %%)",
    )
    g.add_argument(
        "--bootstrap-unit",
        choices=["image", "group"],
        default="image",
        help="what the bootstrap resamples: images, or groups of images (meta group, e.g. "
        "the scene each image was cut from); the same for every detector, so paired.csv "
        "compares detectors on the same resampled data (default image)",
    )
    g.add_argument(
        "--calibrate-on",
        metavar="TARGET",
        default=None,
        help="choose each detector's score threshold on a calibration split for "
        "TARGET ('fa=1': at most 1 false alarm per image; 'f1': best F1) and "
        "report on the disjoint rest",
    )
    g.add_argument(
        "--calibration-fraction",
        type=float,
        default=0.3,
        help="share of each dataset's images in the calibration split",
    )
    g.add_argument(
        "--sweep",
        action="append",
        default=[],
        metavar="KEY=V1,V2,...",
        help="with --calibrate-on: try every detector that has option KEY at each value (all "
        "combinations of the swept options) on the calibration split, keep the setting that "
        "best meets TARGET at its design operating point and report it on the test split; "
        "sweep.csv lists every setting tried (repeatable, e.g. --sweep pfa=1e-3,1e-4,1e-5 "
        "--sweep train=4,8,16)",
    )


def run(args: argparse.Namespace) -> int:
    """The ``run`` sub-command: validate, evaluate, print the summary. The checks that need
    no library come first, so a mistyped number fails at once."""
    from torchsar_eval.options import at_least
    from torchsar_eval.output import check_out

    check_out(args.out, overwrite=args.overwrite, resume=args.resume, discard=args.discard)
    at_least(args.n, "--n", 1)
    at_least(args.batch_size, "--batch-size", 1)
    if args.workers < 1 or args.shard_size < 1:
        raise EvalError("--workers and --shard-size must be >= 1")

    from torchsar_eval.api import evaluate
    from torchsar_eval.commands.run import options
    from torchsar_eval.settings import Calibration, Execution

    detectors, preprocess, despeckle_opts = options.check_run_args(args)
    scoring = options.scoring_from(args)
    execution = Execution(
        batch_size=args.batch_size,
        shard_size=args.shard_size,
        workers=args.workers,
        engine=args.engine,
        address=args.address,
        skip_bad=args.skip_bad,
        max_bad=args.max_bad,
        progress=not args.no_progress,
        device=args.device,
        overlap=not args.no_overlap,
    )
    calibration = None
    sweep = options.parse_sweep(args.sweep)
    if sweep and args.calibrate_on is None:
        raise EvalError(
            "--sweep needs --calibrate-on TARGET (f1 or fa=LEVEL): the settings are "
            "chosen on the calibration split"
        )
    if args.calibrate_on is not None:
        calibration = Calibration(args.calibrate_on, args.calibration_fraction, sweep=sweep or None)
    datasets = args.dataset or DEFAULT_DATASETS
    if args.predictions and len(datasets) != 1:
        raise EvalError("--predictions scores one dataset: name it with --dataset")
    results = evaluate(
        datasets,
        detectors,
        scoring=scoring,
        execution=execution,
        calibration=calibration,
        preprocess=preprocess,
        despeckle=None if args.despeckle is None else {"filter": args.despeckle, **despeckle_opts},
        window_units=args.window_units,
        export_coco=args.export_coco,
        overlay=args.overlay,
        figures=args.figures,
        out=args.out,
        overwrite=args.overwrite,
        resume=args.resume,
        discard=args.discard,
        n=args.n,
        seed=args.seed,
        rank_by=args.rank_by,
    )
    print_summary(results)
    return 0


def print_summary(results: Results) -> None:
    """The console summary: the headline columns, each dataset's throughput and problems;
    datasets by their short labels (the tables keep the full names)."""
    from torchsar_eval.labels import short_labels
    from torchsar_eval.report import throughput
    from torchsar_eval.tables import CONSOLE_COLUMNS

    summary = results.summary.merge(results.timing, on=["dataset", "detector", "images"])
    labels = short_labels([*summary["dataset"], *results.stats])
    summary["dataset"] = summary["dataset"].map(labels)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        print(summary[CONSOLE_COLUMNS].to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    for name, st in results.stats.items():
        print(f"{labels[name]}: {throughput(st)}")
        for f in st["failed"]:
            print(f"  FAILED shard {f['shard']}: {f['error']}")
        for b in st["skipped_items"]:
            print(f"  skipped unreadable {b['file']}")
    print(f"\nwrote {results.out}/: " + " ".join(results.files))
