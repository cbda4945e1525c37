"""``torchsar-eval speckle``: despeckling quality of every speckle filter on datasets.

Writes ``speckle.csv`` / ``speckle.md`` (one row per dataset, filter and window; see
:mod:`torchsar_eval.experiments.speckle.scoring` for the metrics), ``speckle_<dataset>.png``
(before/after crops, :mod:`torchsar_eval.experiments.speckle.panel`) and ``config.json``. Simulated
datasets have a clean reflectivity, so every metric is reported; on ``folder:`` datasets the
clean-image metrics (EPI, PSNR, SSIM) are empty.

The command line is parsed here, at the edge, into :class:`SpeckleOptions`; everything
below takes plain typed values.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

from torchsar_eval.choices import DATASET_SCHEMES, SPECKLE_FILTERS
from torchsar_eval.errors import EvalError

__all__ = ["SpeckleOptions", "add_parser", "evaluate", "parse_options", "run"]

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
        help=f"dataset (repeatable): {', '.join(DATASET_SCHEMES)}; default: sim-scenes",
    )
    p.add_argument(
        "--filters",
        default=",".join(SPECKLE_FILTERS),
        help=f"comma-separated filters (default: all): {', '.join(SPECKLE_FILTERS)}",
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


@dataclass(frozen=True)
class SpeckleOptions:
    """The validated options of one ``speckle`` run."""

    datasets: list[str]
    filters: list[str]
    windows: list[int]
    looks: float | None
    n: int | None
    seed: int
    tile: int
    out: Path


def parse_options(args: argparse.Namespace) -> SpeckleOptions:
    """Check the parsed command line and turn it into :class:`SpeckleOptions`."""
    import torchsar as ts
    from torchsar_eval.output import default_out

    filters = _csv_list(args.filters)
    valid = ", ".join(ts.speckle.FILTERS)
    if not filters:
        raise EvalError(f"--filters must name at least one filter of: {valid}")
    unknown = [f for f in filters if f not in ts.speckle.FILTERS]
    if unknown:
        raise EvalError(f"unknown filter(s) {unknown}; valid: {valid}")
    try:
        windows = _csv_list(args.windows, int)
    except ValueError:
        raise EvalError(
            f"--windows must be comma-separated odd integers, got {args.windows!r}"
        ) from None
    if not windows or any(w < 3 or w % 2 == 0 for w in windows):
        raise EvalError(f"--windows must be odd integers >= 3, got {args.windows!r}")
    if args.looks is not None and not 0 < args.looks < math.inf:
        raise EvalError(f"--looks must be finite and > 0, got {args.looks}")
    if args.tile < 4:
        raise EvalError(f"--tile must be >= 4, got {args.tile}")
    if args.n is not None and args.n < 0:
        raise EvalError(f"--n must be >= 0, got {args.n}")
    return SpeckleOptions(
        datasets=args.dataset or DEFAULT_DATASETS,
        filters=filters,
        windows=windows,
        looks=args.looks,
        n=args.n,
        seed=args.seed,
        tile=args.tile,
        out=args.out or default_out("speckle"),
    )


def run(args: argparse.Namespace) -> int:
    """The command's edge: parse, then :func:`evaluate`."""
    return evaluate(parse_options(args))


def evaluate(opts: SpeckleOptions) -> int:
    """Score every filter and window on every dataset; write the run folder; print the table."""
    import pandas as pd
    import torch

    from torchsar_eval.datasets import make_dataset
    from torchsar_eval.experiments.speckle.panel import despeckling_panel
    from torchsar_eval.experiments.speckle.scoring import samples, score_dataset
    from torchsar_eval.labels import short_labels
    from torchsar_eval.names import slug
    from torchsar_eval.output import result_dir, write_config
    from torchsar_eval.tables import markdown

    datasets = {name: make_dataset(name, n=opts.n, seed=opts.seed) for name in opts.datasets}
    with result_dir(opts.out) as tmp:
        tables = []
        for name, ds in datasets.items():
            items = list(samples(ds))
            if not items:
                raise EvalError(f"dataset {name} has no images")
            tables.append(
                score_dataset(
                    name, items, opts.filters, opts.windows, looks=opts.looks, tile=opts.tile
                )
            )
            looks = opts.looks if opts.looks is not None else (items[0].looks or 1.0)
            panel_window = 7 if 7 in opts.windows else opts.windows[0]
            path = tmp / f"speckle_{slug(name)}.png"
            despeckling_panel(items[0], opts.filters, path, window=panel_window, looks=looks)
        table = pd.concat(tables, ignore_index=True)
        table.to_csv(tmp / "speckle.csv", index=False)
        (tmp / "speckle.md").write_text(markdown(table))
        write_config(
            tmp,
            "speckle",
            {
                "datasets": {n: getattr(d, "options", {}) for n, d in datasets.items()},
                "filters": opts.filters,
                "windows": opts.windows,
                "looks": opts.looks,
                "tile": opts.tile,
                "seed": opts.seed,
                "threads": torch.get_num_threads(),
                "out": str(opts.out),
            },
        )
    shown = table.assign(dataset=table["dataset"].map(short_labels(table["dataset"])))
    print(shown.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    print(
        f"\nwrote {opts.out}/: speckle.csv speckle.md config.json "
        + " ".join(f"speckle_{slug(n)}.png" for n in datasets)
    )
    return 0
