"""``torchsar-eval pfa``: the false-alarm calibration table of the CFAR detectors.

For each detector, each homogeneous clutter model of the simulator (exponential, L-look
gamma, K, G0, log-normal, Weibull) and each design Pfa: the measured Pfa with its binomial
95 % interval, in ``pfa.csv`` / ``pfa.md``, and ``pfa.png`` (measured vs design Pfa).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from torchsar_eval.choices import BUILTIN_DETECTORS

if TYPE_CHECKING:
    import pandas as pd

DEFAULT_DETECTORS = [n for n in BUILTIN_DETECTORS if n != "region"]
DEFAULT_PFAS = (1e-2, 1e-3, 1e-4)


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "pfa",
        help="false-alarm calibration: measured vs design Pfa on homogeneous clutter",
        description="Measure every CFAR's false-alarm rate on homogeneous simulated clutter "
        "of each model at design Pfa 1e-2, 1e-3, 1e-4; write pfa.csv, pfa.md, pfa.png and "
        "config.json.",
    )
    p.add_argument("--detectors", default=None, help="comma-separated (default: all CFARs)")
    p.add_argument("--size", type=int, default=256, help="image side (default 256)")
    p.add_argument("--images", type=int, default=4, help="images per clutter model (default 4)")
    p.add_argument("--pfa", default=",".join(map(str, DEFAULT_PFAS)), help="design Pfa list")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated clutter")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: results/pfa-*)")
    p.add_argument(
        "--dataset",
        action="append",
        metavar="NAME",
        help="measure on this dataset's clutter pixels instead of simulated homogeneous "
        "clutter (repeatable; e.g. folder:PATH, hrsid:DIR): real clutter vs the models",
    )
    p.add_argument("--n", type=int, default=None, help="images per --dataset (default: all)")
    p.add_argument("--batch-size", type=int, default=8, help="images per detector call")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import pandas as pd
    from tqdm import tqdm

    from torchsar_eval.datasets import make_dataset
    from torchsar_eval.experiments.pfa.calibration import CLUTTER, measure, measure_dataset
    from torchsar_eval.labels import short_labels
    from torchsar_eval.options import at_least, floats, names
    from torchsar_eval.output import default_out, result_dir, write_config
    from torchsar_eval.registry import BUILTIN
    from torchsar_eval.tables import markdown

    wanted = ",".join(DEFAULT_DETECTORS) if args.detectors is None else args.detectors
    specs = [BUILTIN[n] for n in names(wanted, "--detectors", BUILTIN, what="detector")]
    pfas = floats(args.pfa, "--pfa", above=0, below=1)
    at_least(args.size, "--size", 16)
    at_least(args.images, "--images", 1)
    out = args.out or default_out("pfa")
    tables = []
    datasets = {d: make_dataset(d, n=args.n, seed=args.seed) for d in args.dataset or []}
    at_least(args.batch_size, "--batch-size", 1)
    with result_dir(out) as tmp:
        for name, ds in tqdm(datasets.items(), desc="datasets", disable=args.no_progress):
            tables.append(measure_dataset(specs, name, ds, pfas, args.batch_size))
        cases = [] if datasets else CLUTTER
        for i, case in enumerate(tqdm(cases, desc="clutter", disable=args.no_progress)):
            x = case.sample(args.images, args.size, args.seed + i)
            tables.append(measure(specs, case, x, pfas))
        table = pd.concat(tables, ignore_index=True)
        table.to_csv(tmp / "pfa.csv", index=False)
        (tmp / "pfa.md").write_text(markdown(_wide(table)))
        plot_pfa(table, tmp / "pfa.png")
        write_config(
            tmp,
            "pfa",
            {
                "detectors": {s.name: dict(s.params) for s in specs},
                "clutter": [c.__dict__ for c in CLUTTER] if not datasets else None,
                "datasets": {n: getattr(d, "options", {}) for n, d in datasets.items()},
                "design_pfa": pfas,
                "size": args.size,
                "images": args.images,
                "seed": args.seed,
                "note": "detectors with a looks option get the clutter's looks",
            },
        )
    shown = table.assign(clutter=table["clutter"].map(short_labels(table["clutter"])))
    print(_wide(shown).to_string(float_format=lambda v: f"{v:.3g}"))
    print(f"\nwrote {out}/: pfa.csv pfa.md pfa.png config.json")
    return 0


def _wide(table: pd.DataFrame) -> pd.DataFrame:
    """Measured / design Pfa ratio: detectors x (clutter, design Pfa)."""
    wide = table.pivot_table(
        index="detector", columns=["clutter", "design_pfa"], values="ratio", sort=False
    )
    wide.columns = [f"{c} @{p:g}" for c, p in wide.columns]
    return wide.reset_index()


def plot_pfa(table: pd.DataFrame, path: Path) -> None:
    """One panel per clutter model: measured vs design Pfa (log-log) with 95 % intervals;
    a detector without any false alarm is drawn as an open triangle at the interval's upper
    bound. A detector missing from a panel is named there."""
    from torchsar_eval.labels import short_label
    from torchsar_eval.plots import detector_style, legend_handles, log_axis, pyplot, save, titled

    plt = pyplot()
    cases = list(dict.fromkeys(table["clutter"]))
    everyone = list(dict.fromkeys(table["detector"]))
    cols = min(3, len(cases))
    rows = (len(cases) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.9 * rows + 0.6), squeeze=False)
    for ax, case in zip(axes.flat, cases, strict=False):
        sub = table[table["clutter"] == case]
        for name, df in sub.groupby("detector", sort=False):
            st = detector_style(name)
            seen = df[df["false_alarms"] > 0]
            y = seen["measured_pfa"]
            err = [y - seen["ci_low"], seen["ci_high"] - y]
            ax.errorbar(seen["design_pfa"], y, yerr=err, ms=4, capsize=2, **st)
            none = df[df["false_alarms"] == 0]  # no false alarm: mark the 95 % upper bound
            ax.plot(none["design_pfa"], none["ci_high"], "v", ms=5, color=st["color"], mfc="none")
        lim = [sub["design_pfa"].min() / 3, sub["design_pfa"].max() * 3]
        ax.plot(lim, lim, "k--", lw=0.8)
        measured = sub.loc[sub["false_alarms"] > 0, "measured_pfa"]
        log_axis(ax, "x", sub["design_pfa"])
        low = sub.loc[sub["false_alarms"] > 0, "ci_low"]
        log_axis(ax, "y", [*sub["design_pfa"], *measured, *low, *sub["ci_high"]])
        ax.set(xlabel="design Pfa", ylabel="measured Pfa")
        missing = {n: "not measured" for n in everyone if n not in set(sub["detector"])}
        titled(ax, short_label(case), missing, width=48)
        ax.grid(True, which="major", alpha=0.3)
    for ax in list(axes.flat)[len(cases) :]:
        ax.axis("off")
    handles = legend_handles(everyone)
    fig.legend(
        handles=handles,
        loc="lower center",
        ncol=min(len(handles), 7),
        fontsize=8,
        title="open triangle: no false alarm (95 % upper bound)",
        title_fontsize=8,
    )
    legend_rows = -(-len(handles) // 7)
    save(fig, path, rect=(0, (0.06 * legend_rows + 0.05) / rows, 1, 1))
