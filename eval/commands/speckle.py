"""``torchsar-eval speckle``: despeckling quality of every speckle filter on datasets.

Writes ``speckle.csv`` / ``speckle.md`` (one row per dataset, filter and window; see
:mod:`eval.despeckling` for the metrics), ``speckle_<dataset>.png`` (before/after crops)
and ``config.json``. Simulated datasets have a clean reflectivity, so every metric is
reported; on ``folder:`` datasets the clean-image metrics (EPI, PSNR, SSIM) are empty.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd
import torch

import torchsar as ts
from eval.datasets import DATASETS, make_dataset
from eval.despeckling import plot_panel, samples, score_dataset
from eval.errors import EvalError
from eval.output import default_out, result_dir, write_config
from eval.plots import slug
from eval.tables import markdown

__all__ = ["add_parser", "run"]

DEFAULT_DATASETS = ["sim-scenes"]


def _csv_list(text: str, kind=str) -> list:
    return [kind(v.strip()) for v in text.split(",") if v.strip()]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "speckle",
        help="score speckle filters (ENL, ratio image, edges, PSNR, SSIM, speed)",
        description="Filter every image with every speckle filter and window; write "
        "speckle.csv, speckle.md, speckle_<dataset>.png and config.json.",
    )
    p.add_argument(
        "--dataset",
        action="append",
        metavar="NAME",
        help=f"dataset (repeatable): {', '.join(DATASETS)}; default: sim-scenes",
    )
    p.add_argument(
        "--filters",
        default=",".join(ts.speckle.FILTERS),
        help=f"comma-separated filters (default: all): {','.join(ts.speckle.FILTERS)}",
    )
    p.add_argument("--windows", default="5,7", help="comma-separated odd windows (default 5,7)")
    p.add_argument(
        "--looks",
        type=float,
        default=None,
        help="speckle looks (default: from the simulator, else 1)",
    )
    p.add_argument("--n", type=int, default=None, help="images per dataset (default: per dataset)")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated datasets")
    p.add_argument("--tile", type=int, default=32, help="ENL tile side in pixels (default 32)")
    p.add_argument(
        "--out", type=Path, default=None, help="output folder (default: results/speckle-*)"
    )
    p.set_defaults(func=run)


def _check(args: argparse.Namespace) -> tuple[list[str], list[int]]:
    filters = _csv_list(args.filters)
    unknown = [f for f in filters if f not in ts.speckle.FILTERS]
    if unknown or not filters:
        raise EvalError(f"unknown filter(s) {unknown}; valid: {', '.join(ts.speckle.FILTERS)}")
    try:
        windows = _csv_list(args.windows, int)
    except ValueError:
        raise EvalError(
            f"--windows must be comma-separated odd integers, got {args.windows!r}"
        ) from None
    if not windows or any(w < 3 or w % 2 == 0 for w in windows):
        raise EvalError(f"--windows must be odd integers >= 3, got {args.windows!r}")
    if args.looks is not None and not args.looks > 0:
        raise EvalError(f"--looks must be > 0, got {args.looks}")
    if args.tile < 4:
        raise EvalError(f"--tile must be >= 4, got {args.tile}")
    return filters, windows


def run(args: argparse.Namespace) -> int:
    filters, windows = _check(args)
    names = args.dataset or DEFAULT_DATASETS
    datasets = {name: make_dataset(name, n=args.n, seed=args.seed) for name in names}
    out = args.out or default_out("speckle")
    with result_dir(out) as tmp:
        tables = []
        for name, ds in datasets.items():
            items = list(samples(ds))
            if not items:
                raise EvalError(f"dataset {name} has no images")
            tables.append(
                score_dataset(name, items, filters, windows, looks=args.looks, tile=args.tile)
            )
            looks = args.looks if args.looks is not None else (items[0].looks or 1.0)
            panel_window = 7 if 7 in windows else windows[0]
            plot_panel(items[0], filters, panel_window, looks, tmp / f"speckle_{slug(name)}.png")
        table = pd.concat(tables, ignore_index=True)
        table.to_csv(tmp / "speckle.csv", index=False)
        (tmp / "speckle.md").write_text(markdown(table))
        write_config(
            tmp,
            "speckle",
            {
                "datasets": {n: getattr(d, "options", {}) for n, d in datasets.items()},
                "filters": filters,
                "windows": windows,
                "looks": args.looks,
                "tile": args.tile,
                "seed": args.seed,
                "threads": torch.get_num_threads(),
                "out": str(out),
            },
        )
    print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    print(
        f"\nwrote {out}/: speckle.csv speckle.md config.json "
        + " ".join(f"speckle_{slug(n)}.png" for n in datasets)
    )
    return 0
