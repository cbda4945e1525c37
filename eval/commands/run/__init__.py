"""``torchsar-eval run``: evaluate detectors on datasets; summary, ROC tables and plots.

The command-line edge: options are parsed and validated here, then turned into the plain
typed settings of :mod:`torchsar_eval.commands.run.evaluate` (how shards run, calibration)
and handed to :func:`~torchsar_eval.commands.run.evaluate.execute`;
:mod:`torchsar_eval.commands.run.report` writes the tables and plots.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from torchsar._checks import TorchSARError
from torchsar.metrics import Matching
from torchsar.objects import ObjectRules
from torchsar.speckle import FILTERS
from torchsar_eval.commands.run.evaluate import Calibration, Execution, RunPlan, execute
from torchsar_eval.commands.run.report import print_summary
from torchsar_eval.datasets import DATASETS, make_dataset
from torchsar_eval.detectors import DETECTORS
from torchsar_eval.errors import EvalError
from torchsar_eval.options import check_run_args
from torchsar_eval.output import default_out
from torchsar_eval.runner import DEFAULT_MATCH, DEFAULT_RULES, Scoring

__all__ = ["DEFAULT_DATASETS", "DEFAULT_MATCH", "DEFAULT_RULES", "add_parser", "run"]

DEFAULT_DATASETS = ["sim-chips", "sim-scenes"]


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
    """The ``run`` sub-command: validate, build the datasets, execute, print the summary."""
    specs, preprocess, despeckle_opts = check_run_args(args)
    if args.workers < 1 or args.shard_size < 1:
        raise EvalError("--workers and --shard-size must be >= 1")
    scoring = scoring_from(args)
    execution = Execution(
        batch_size=args.batch_size,
        shard_size=args.shard_size,
        workers=args.workers,
        engine=args.engine,
        address=args.address,
        skip_bad=args.skip_bad,
        progress=not args.no_progress,
    )
    calibration = None
    if args.calibrate_on is not None:
        calibration = Calibration(args.calibrate_on, args.calibration_fraction)
    plan = RunPlan(
        specs=specs,
        scoring=scoring,
        preprocess=preprocess,
        despeckle=None if args.despeckle is None else {"filter": args.despeckle, **despeckle_opts},
        execution=execution,
        calibration=calibration,
        window_units=args.window_units,
        export_coco=args.export_coco,
        seed=args.seed,
    )
    datasets = {
        name: make_dataset(name, n=args.n, seed=args.seed)
        for name in (args.dataset or DEFAULT_DATASETS)
    }
    out = args.out or default_out("run")
    stats, files = execute(plan, datasets, out, resume=args.resume)
    print_summary(out, stats, files)
    return 0
