"""``torchsar-eval run``: evaluate detectors on datasets; summary, ROC tables and plots."""

from __future__ import annotations

import argparse
from pathlib import Path

from eval.datasets import DATASETS, make_dataset
from eval.detectors import DETECTORS
from eval.options import check_run_args
from eval.output import default_out, result_dir, write_config
from eval.plots import plot_roc, slug
from eval.runner import evaluate
from eval.tables import markdown, pixel_roc_table, roc_table, summary_table
from torchsar.speckle import FILTERS

DEFAULT_DATASETS = ["sim-chips", "sim-scenes"]

SUMMARY_SHOWN = [
    "dataset",
    "detector",
    "images",
    "pd_pixel",
    "pfa_pixel",
    "pd_object",
    "false_alarms_per_image",
    "fragmentation",
    "fom",
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
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    specs, preprocess, despeckle_opts = check_run_args(args)
    datasets = {
        name: make_dataset(name, n=args.n, seed=args.seed)
        for name in (args.dataset or DEFAULT_DATASETS)
    }
    out = args.out or default_out("run")
    with result_dir(out) as tmp:
        results = {
            name: evaluate(
                ds,
                specs,
                batch_size=args.batch_size,
                preprocess=preprocess,
                progress=not args.no_progress,
                desc=name,
            )
            for name, ds in datasets.items()
        }
        summary = summary_table(results)
        summary.to_csv(tmp / "summary.csv", index=False)
        roc = roc_table(results)
        roc.to_csv(tmp / "roc.csv", index=False)
        pixel = pixel_roc_table(results)
        pixel.to_csv(tmp / "roc_pixel.csv", index=False)
        (tmp / "summary.md").write_text(markdown(summary))
        for name in datasets:
            plot_roc(
                pixel[pixel.dataset == name],
                roc[roc.dataset == name],
                summary[summary.dataset == name],
                tmp / f"roc_{slug(name)}.png",
                name,
            )
        write_config(
            tmp,
            "run",
            {
                "datasets": {n: getattr(d, "options", {}) for n, d in datasets.items()},
                "detectors": {s.name: dict(s.params) for s in specs},
                "despeckle": None
                if args.despeckle is None
                else {"filter": args.despeckle, **despeckle_opts},
                "batch_size": args.batch_size,
                "seed": args.seed,
                "out": str(out),
            },
        )
    print(summary[SUMMARY_SHOWN].to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    print(
        f"\nwrote {out}/: summary.csv roc.csv roc_pixel.csv summary.md config.json "
        + " ".join(f"roc_{slug(n)}.png" for n in datasets)
    )
    return 0
