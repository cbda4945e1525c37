"""``torchsar-eval autofocus``: the sparse-autofocus experiment table, figures and detection.

Writes ``autofocus.csv`` (mean and spread per method x error type), ``autofocus_scenes.csv``
(one row per scene), ``autofocus.md``, ``detection.csv`` (Pd / Pfa after each imaging method),
``panel_<error>.png`` (the seed's figures: conventional / L_p / proposed, with and without
error) and ``config.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Collection
from pathlib import Path
from typing import TYPE_CHECKING

from torchsar_eval.choices import (
    AUTOFOCUS_DEFAULTS,
    AUTOFOCUS_ERRORS,
    AUTOFOCUS_METHODS,
    DEFAULT_AUTOFOCUS_METHODS,
)
from torchsar_eval.errors import EvalError
from torchsar_eval.paths import SHARED_DATA

if TYPE_CHECKING:
    import pandas as pd
    import torch

    from torchsar.io.gotcha import GotchaPass

METRICS = [
    "corr",
    "success",
    "phase_rmse",
    "mag_nmse",
    "entropy",
    "tbr_db",
    "iterations",
    "seconds",
]
DEFAULT_GOTCHA = SHARED_DATA / "gotcha"
DETECTION = ["pd_ca", "pfa_ca", "pd_global", "pfa_global"]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "autofocus",
        help="sparse autofocus vs conventional / L_p / PGA / min-entropy on simulated scenes",
        description=__doc__.splitlines()[0],
    )
    d = AUTOFOCUS_DEFAULTS
    p.add_argument(
        "--out", type=Path, default=None, help="output folder (default: results/autofocus-*)"
    )
    p.add_argument("--scenes", type=int, default=d["scenes"], help="random scenes per error type")
    p.add_argument("--size", type=int, default=d["size"], help="image size (pixels, square)")
    p.add_argument("--density", type=float, default=d["density"], help="fraction of bright pixels")
    p.add_argument("--snr", type=float, default=d["snr_db"], help="phase-history SNR in dB")
    p.add_argument("--seed", type=int, default=d["seed"], help="seed of the simulated scenes")
    p.add_argument(
        "--errors",
        default=",".join(AUTOFOCUS_ERRORS),
        help=f"comma-separated error types (default: all): {', '.join(AUTOFOCUS_ERRORS)}",
    )
    p.add_argument(
        "--methods",
        default=",".join(DEFAULT_AUTOFOCUS_METHODS),
        help=f"comma-separated methods (default: all but sparse-keep-restarts): "
        f"{', '.join(AUTOFOCUS_METHODS)}",
    )
    p.add_argument("--pfa", type=float, default=d["pfa"], help="CA-CFAR design Pfa")
    p.add_argument(
        "--gotcha",
        type=Path,
        default=None,
        help="GOTCHA folder for the real-data injected-error experiment (must hold the "
        f"pass-1 HH files; default: {DEFAULT_GOTCHA}, skipped with a note when absent)",
    )
    p.add_argument("--gotcha-trials", type=int, default=3, help="injected errors per type")
    p.add_argument("--no-gotcha", action="store_true", help="skip the GOTCHA experiment")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=run)


def _names(text: str, allowed: Collection[str], what: str) -> list[str]:
    names = [t.strip() for t in text.split(",") if t.strip()]
    bad = [n for n in names if n not in allowed]
    if bad:
        raise EvalError(f"unknown {what} {bad}; choose from {list(allowed)}")
    return names


def summarise(rows: pd.DataFrame, columns: list[str]) -> pd.DataFrame:
    """Mean and standard deviation per (error, method), in the run order."""
    import pandas as pd

    g = rows.groupby(["error", "method"], sort=False)[columns]
    mean, std = g.mean().add_suffix("_mean"), g.std().add_suffix("_std")
    out = pd.concat([mean, std], axis=1)
    order = [c + s for c in columns for s in ("_mean", "_std")]
    out = out[order].reset_index()
    out.insert(2, "scenes", g.size().to_numpy())
    return out


def _db(x: torch.Tensor) -> torch.Tensor:
    import torch

    a = x.abs()
    return 20 * torch.log10(a / a.max().clamp_min(1e-30) + 1e-6).clamp_min(-40)


PANEL_METHODS = {
    "conventional": "conventional, with error",
    "lp": "L_p, with error",
    "sparse-autofocus": "proposed (sparse autofocus)",
}
"""The methods the seed figure shows (the table has every method)."""


def panel_images(name: str, data: dict, formed: dict) -> list[tuple[str, torch.Tensor]]:
    """The seed figure's images of scene 0, magnitudes ``(H, W)``: the true scene, the
    clean conventional and L_p images, then the corrupted conventional and L_p images and
    the sparse-autofocus image where those methods ran.

    A constant plus linear phase error is a circular shift of the image that no method can
    observe (the estimate's linear part is arbitrary), so every image is shown circularly
    shifted to best match the true scene (and, for 2-D errors, possibly as its twin, the
    flipped image), as the table scores it.
    """
    import torchsar.imaging as ti
    from torchsar_eval.experiments.autofocus.experiment import ERROR_CASES

    truth = data["f"][:1].abs()
    flip = ERROR_CASES[name].kind == "2d"
    clean = data["clean"][:1]
    images = [
        ("conventional, no error", ti.ifft2c(clean).unsqueeze(1)),
        ("L_p, no error", ti.lp_image(clean)),
    ]
    images += [(title, formed[m].image[:1]) for m, title in PANEL_METHODS.items() if m in formed]
    shown = [("true scene", truth[0, 0])]
    for title, img in images:
        aligned, _ = ti.align(img.abs().to(truth.dtype), truth, flip=flip)
        shown.append((title, aligned[0, 0]))
    return shown


def autofocus_panel(name: str, data: dict, formed: dict, path: Path) -> None:
    """Seed figure layout for scene 0: truth, clean conventional / L_p, corrupted, proposed
    (see :func:`panel_images`); the methods left out are named."""
    from torchsar_eval.plots import not_shown, pyplot, save

    plt = pyplot()
    panels = panel_images(name, data, formed)
    left = {m: "in autofocus.csv" for m in formed if m not in PANEL_METHODS}
    left.update({m: "not run" for m in PANEL_METHODS if m not in formed})
    fig, axes = plt.subplots(1, len(panels), figsize=(2.6 * len(panels), 3.2))
    for ax, (title, img) in zip(axes, panels, strict=True):
        ax.imshow(_db(img).numpy(), cmap="gray", vmin=-40, vmax=0)
        ax.set_title(title, fontsize=8)
        ax.axis("off")
    note = not_shown(left)
    fig.suptitle(
        f"phase error {name} (dB, 40 dB range; each image circularly shifted to the "
        "true scene: a linear phase error is an unobservable shift)"
        + (f"\n{note}" if note else ""),
        fontsize=8,
    )
    save(fig, path)


def gotcha_data(folder: Path | None, enabled: bool) -> tuple[GotchaPass | None, str]:
    """Read the GOTCHA pass before any work: ``(data or None, note)``.

    An explicit folder must exist and hold readable GOTCHA files (else :class:`EvalError`,
    one line); the default folder is skipped with a note when absent.
    """
    from torchsar.io.gotcha import read_gotcha

    if not enabled:
        return None, "GOTCHA experiment skipped (--no-gotcha)"
    path = DEFAULT_GOTCHA if folder is None else Path(folder)
    if not path.is_dir():
        if folder is None:
            return None, f"GOTCHA experiment skipped: default folder {path} absent"
        raise EvalError(f"--gotcha folder {path} does not exist or is not a folder")
    try:
        return read_gotcha(path), f"GOTCHA experiment on {path}"
    except FileNotFoundError as exc:
        raise EvalError(f"--gotcha: {exc}") from None


def gotcha_table(data: GotchaPass, tmp: Path, *, trials: int, seed: int) -> None:
    """The GOTCHA injected-error experiment: gotcha.csv, gotcha_trials.csv, gotcha.png."""
    import pandas as pd

    from torchsar_eval.experiments.autofocus.gotcha import run_gotcha

    rows, panel = run_gotcha(data, trials=trials, seed=seed)
    trials = pd.DataFrame(rows)
    trials.to_csv(tmp / "gotcha_trials.csv", index=False)
    cols = ["phase_rmse", "entropy", "reference_entropy", "reflector_peak_ratio", "seconds"]
    summarise(trials, cols).to_csv(tmp / "gotcha.csv", index=False)
    gotcha_figure(panel, tmp / "gotcha.png")


def gotcha_figure(panel: dict[str, torch.Tensor], path: Path) -> None:
    """The GOTCHA images as a grid: one row per injected error type, one column per
    correction method (``"error / method"`` keys), the reference image first."""
    from torchsar_eval.plots import pyplot, save

    plt = pyplot()
    cells = [k.split(" / ", 1) for k in panel if " / " in k]
    errors = list(dict.fromkeys(e for e, _ in cells))
    methods = list(dict.fromkeys(m for _, m in cells))
    rows, cols = max(1, len(errors)), 1 + len(methods)
    fig, axes = plt.subplots(rows, cols, figsize=(2.5 * cols, 3.1 * rows + 0.5), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")

    def show(ax, image: torch.Tensor, title: str) -> None:
        ax.imshow(_db(image.sqrt()).numpy(), cmap="gray", vmin=-40, vmax=0, origin="lower")
        ax.set_title(title, fontsize=8)

    if "reference" in panel:
        show(axes[0, 0], panel["reference"], "reference (AFRL autofocus)")
    for r, error in enumerate(errors):
        for c, method in enumerate(methods, start=1):
            key = f"{error} / {method}"
            if key in panel:
                show(axes[r, c], panel[key], f"{error}\n{method}")
    fig.suptitle(
        "GOTCHA pass 1 HH: injected phase error (rows) corrected by each method "
        "(columns); dB, 40 dB range",
        fontsize=9,
    )
    save(fig, path)


def run(args: argparse.Namespace) -> int:
    import pandas as pd
    from tqdm import tqdm

    from torchsar_eval.experiments.autofocus.experiment import Config, run_error_case
    from torchsar_eval.names import slug
    from torchsar_eval.output import default_out, result_dir, write_config
    from torchsar_eval.tables import markdown

    errors = _names(args.errors, AUTOFOCUS_ERRORS, "error types")
    methods = _names(args.methods, AUTOFOCUS_METHODS, "methods")
    if args.scenes < 1 or args.size < 8:
        raise EvalError("need --scenes >= 1 and --size >= 8")
    gotcha, gotcha_note = gotcha_data(args.gotcha, not args.no_gotcha)
    cfg = Config(
        scenes=args.scenes,
        size=args.size,
        density=args.density,
        snr_db=args.snr,
        seed=args.seed,
        pfa=args.pfa,
    )
    out = args.out or default_out("autofocus")
    rows = []
    with result_dir(out) as tmp:
        for name in tqdm(errors, desc="autofocus", disable=args.no_progress):
            r, data, formed = run_error_case(name, cfg, methods)
            rows += r
            autofocus_panel(name, data, formed, tmp / f"panel_{slug(name)}.png")
        scenes = pd.DataFrame(rows)
        scenes.to_csv(tmp / "autofocus_scenes.csv", index=False)
        table = summarise(scenes, METRICS)
        table.to_csv(tmp / "autofocus.csv", index=False)
        detection = summarise(scenes, DETECTION)
        detection.to_csv(tmp / "detection.csv", index=False)
        shown = ["error", "method", "scenes"] + [c + "_mean" for c in METRICS]
        (tmp / "autofocus.md").write_text(
            markdown(table[shown])
            + "\n"
            + markdown(detection[["error", "method"] + [c + "_mean" for c in DETECTION]])
        )
        if gotcha is not None:
            gotcha_table(gotcha, tmp, trials=args.gotcha_trials, seed=args.seed)
        options = {**dataclasses.asdict(cfg), "errors": errors, "methods": methods}
        options.update(
            gotcha=gotcha_note, gotcha_trials=args.gotcha_trials, no_gotcha=args.no_gotcha
        )
        write_config(tmp, "autofocus", options)
    print(markdown(table[shown]))
    print(gotcha_note)
    print(f"results in {out}")
    return 0
