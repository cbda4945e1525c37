"""``torchsar-eval compare-region``: region-growing CFAR against window CFARs at their best.

On the default simulated scenes and on the MSTAR SARBake chips (skipped with a note when
the folder is absent), the region CFAR with the paper's preset and with ours is compared with
every registered window CFAR (CA, OS, GO, SO, VI, AC, two-parameter) at its best setting:
``guard x train x pfa`` swept on a tuning set (simulated: other scenes, different seed;
MSTAR: every 5th chip, and the summary reports on the other chips only) and chosen by FoM.
The region CFAR is *not* tuned per dataset. Writes ``summary.csv`` (object Pd, false alarms
per image, fragmentation, mean IoU, FoM), ``timing.csv`` (ms per image), ``summary.md`` (both,
and the chosen settings), ``chosen.csv``, ``panel_<dataset>.png`` and ``config.json``.
"""

from __future__ import annotations

import argparse
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from torchsar_eval.choices import BUILTIN_DETECTORS
from torchsar_eval.errors import EvalError
from torchsar_eval.paths import SHARED_DATA

if TYPE_CHECKING:
    from torchsar_eval.detector import Detector

WINDOW_CFARS = ["ca", "os", "go", "so", "vi", "ac", "two_parameter"]
TUNE_EVERY = 5
"""MSTAR: every 5th chip tunes the window CFARs; the summary reports on the others."""
MSTAR = SHARED_DATA / "mstar_sarbake"
SHOWN = [
    "dataset",
    "detector",
    "images",
    "pd_object",
    "false_alarms_per_image",
    "f1",
    "ap50",
    "fragmentation",
    "mean_iou",
    "fom",
    "ms_per_image",
]


@dataclass(frozen=True)
class Sweep:
    """The tuning grid and how to run it (parsed from the command line)."""

    guards: list[int]
    trains: list[int]
    pfas: list[float]
    window_cfars: list[str]
    max_ring: int
    batch_size: int


def _sweep(args: argparse.Namespace) -> Sweep:
    """Check every option before any work; the parsed sweep."""
    from torchsar_eval.options import at_least, floats, ints, names

    at_least(args.n, "--n", 1)
    at_least(args.n_tune, "--n-tune", 1)
    at_least(args.mstar_n, "--mstar-n", 2)
    at_least(args.batch_size, "--batch-size", 1)
    at_least(args.max_ring, "--max-ring", 1)
    window_cfars = [d for d in BUILTIN_DETECTORS if d != "region"]
    return Sweep(
        guards=ints(args.guards, "--guards", minimum=0),
        trains=ints(args.trains, "--trains", minimum=1),
        pfas=floats(args.pfas, "--pfas", above=0, below=1),
        window_cfars=names(args.window_cfars, "--window-cfars", window_cfars, what="window CFAR"),
        max_ring=args.max_ring,
        batch_size=args.batch_size,
    )


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "compare-region",
        help="region-growing CFAR vs window CFARs at their best settings",
        description=__doc__.splitlines()[0],
    )
    p.add_argument(
        "--out", type=Path, default=None, help="output folder (default: results/compare-region-*)"
    )
    p.add_argument(
        "--sim",
        action="append",
        choices=["sim-scenes", "sim-chips"],
        help="simulated dataset (repeatable; default: sim-scenes)",
    )
    p.add_argument("--n", type=int, default=3, help="simulated evaluation images")
    p.add_argument("--n-tune", type=int, default=2, help="simulated tuning images")
    p.add_argument("--seed", type=int, default=0, help="seed of the evaluation scenes")
    p.add_argument("--mstar", type=Path, default=MSTAR, help="MSTAR SARBake folder")
    p.add_argument("--mstar-n", type=int, default=None, help="use only the first N chips (N >= 2)")
    # The default sweep is the one behind the published evidence table; widen it with these
    # options on an idle machine (GO/SO threshold solves dominate large grids).
    p.add_argument("--guards", default="4,16,32", help="guard sweep (default 4,16,32)")
    p.add_argument("--trains", default="4,12", help="train sweep (default 4,12)")
    p.add_argument("--pfas", default="1e-3,1e-5,1e-7,1e-9", help="pfa sweep")
    p.add_argument(
        "--window-cfars",
        default=",".join(WINDOW_CFARS),
        help=f"comma-separated window CFARs to compare (default: {', '.join(WINDOW_CFARS)}; "
        "GO/SO solve their exact threshold per window, pfa and border count: seconds each "
        "for large windows)",
    )
    p.add_argument(
        "--max-ring",
        type=int,
        default=1000,
        help="skip OS-CFAR windows with more training cells than this (its cost grows with "
        "the ring; the other detectors cost the same for every window)",
    )
    p.add_argument("--batch-size", type=int, default=4, help="images per detector call")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    p.set_defaults(func=run)


def _datasets(args: argparse.Namespace, notes: list[str]) -> dict[str, tuple[object, object]]:
    """``{name: (tuning dataset, evaluation dataset)}``."""
    from torch.utils.data import Subset

    from torchsar_eval.datasets import make_dataset

    out = {
        sim: (
            make_dataset(sim, n=args.n_tune, seed=args.seed + 1000),
            make_dataset(sim, n=args.n, seed=args.seed),
        )
        for sim in args.sim or ["sim-scenes"]
    }
    if args.mstar.is_dir():
        ds = make_dataset(f"folder:{args.mstar}", n=args.mstar_n)
        tune = range(0, len(ds), TUNE_EVERY)
        report = [i for i in range(len(ds)) if i % TUNE_EVERY]
        if not report:
            raise EvalError(f"MSTAR: {len(ds)} chip(s) leave none to report on after tuning")
        out["mstar_sarbake"] = (Subset(ds, tune), Subset(ds, report))
        notes.append(
            f"mstar_sarbake: window CFARs tuned on {len(tune)} chips (every {TUNE_EVERY}th), "
            f"reported on the other {len(report)}"
        )
    else:
        notes.append(f"MSTAR folder {args.mstar} not found: skipped")
    return out


def _ring(q: dict) -> int:
    return (2 * (q["guard"] + q["train"]) + 1) ** 2 - (2 * q["guard"] + 1) ** 2


def _region_specs() -> list[Detector]:
    import torchsar as ts
    from torchsar_eval.detector import Detector

    return [
        Detector("region-paper", ts.region.region_cfar, {"preset": "paper"}),
        Detector("region", ts.region.region_cfar, {}),
    ]


def _tuned(tune, sweep: Sweep, notes: list[str], name: str) -> tuple[list[Detector], list]:
    """Each requested window CFAR at its best grid point on the tuning set."""
    from torchsar_eval.batches import batches
    from torchsar_eval.detector import Detector
    from torchsar_eval.experiments.compare_region.sweep import best_setting, window_grid
    from torchsar_eval.registry import BUILTIN

    tb = list(batches(tune, sweep.batch_size))
    grid = window_grid(sweep.guards, sweep.trains, sweep.pfas)
    specs, chosen = [], []
    for det in sweep.window_cfars:
        g = grid if det != "os" else [q for q in grid if _ring(q) <= sweep.max_ring]
        if not g:
            notes.append(f"{name}: no OS window within --max-ring {sweep.max_ring}: skipped")
            continue
        c = best_setting(BUILTIN[det], g, tb)
        specs.append(Detector(det, BUILTIN[det].fn, c.params))
        chosen.append({"dataset": name, "detector": det, **c.params, "tuning_fom": c.scores["fom"]})
    return specs, chosen


def run(args: argparse.Namespace) -> int:
    import pandas as pd

    from torchsar_eval.experiments.compare_region.panel import detection_panel
    from torchsar_eval.names import file_slugs, slug
    from torchsar_eval.output import default_out, result_dir, write_config
    from torchsar_eval.runner import run_detectors
    from torchsar_eval.tables import markdown, summary_table, timing_table

    sweep = _sweep(args)
    notes: list[str] = []
    out = args.out or default_out("compare-region")
    results, chosen = {}, []
    with result_dir(out) as tmp:
        datasets = _datasets(args, notes)
        slugs = file_slugs(datasets, slug)
        for name, (tune, ds) in datasets.items():
            specs, rows = _tuned(tune, sweep, notes, name)
            specs = _region_specs() + specs
            chosen += rows
            results[name] = run_detectors(
                ds, specs, batch_size=sweep.batch_size, progress=not args.no_progress, desc=name
            )
            detection_panel(
                [ds[i] for i in range(min(3, len(ds)))], specs, tmp / f"panel_{slugs[name]}.png"
            )
        summary_table(results).to_csv(tmp / "summary.csv", index=False)
        timing_table(results).to_csv(tmp / "timing.csv", index=False)
        summary = summary_table(results).merge(
            timing_table(results), on=["dataset", "detector", "images"]
        )
        pd.DataFrame(chosen).to_csv(tmp / "chosen.csv", index=False)
        text = markdown(summary[SHOWN]) + "\n\nChosen window settings:\n\n"
        text += markdown(pd.DataFrame(chosen)) + "\n" + "".join(f"\n- {n}" for n in notes)
        (tmp / "summary.md").write_text(text + "\n")
        options = {k: v for k, v in vars(args).items() if k != "func"}
        write_config(tmp, "compare-region", {**options, **asdict(sweep)})
    print(summary[SHOWN].to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    for n in notes:
        print(f"note: {n}")
    print(f"\nwrote {out}/: summary.csv timing.csv summary.md chosen.csv panel_*.png config.json")
    return 0
