"""Figures of ``torchsar-eval movers``: pair displacements per subpatch and the speed ladder."""

from __future__ import annotations

from itertools import combinations
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd
import torch

__all__ = ["plot_ladder", "plot_pairs"]

AXES = ("range", "azimuth")


def _pair_values(data: dict[str, tuple[torch.Tensor, torch.Tensor]], kind: int, period):
    """``{"a-b": (P, 2)}``: pair separation in each subpatch minus that in subpatch 1.

    Folded into +-period / 2 (the images are periodic with the sampled extent).
    """
    out = {}
    for a, b in combinations(sorted(data), 2):
        d = data[a][kind] - data[b][kind]
        d = d - d[0]
        out[f"{a}-{b}"] = (d - period * torch.floor(d / period + 0.5)).numpy()
    return out


def plot_pairs(data, path: Path, title: str, period: torch.Tensor) -> None:
    """The paper's Figures 5-8: displacement of each target pair per subpatch ("A#x").

    Rows: range / azimuth component. Columns: stationary pairs / pairs with the mover "M".
    Filled markers: raw image positions (the paper's measurement); hollow: after the
    planar-distortion correction.
    """
    fig, axes = plt.subplots(2, 2, figsize=(11, 6.5), sharey="row", squeeze=False)
    raw, corr = _pair_values(data, 0, period), _pair_values(data, 1, period)
    for col, with_mover in enumerate((False, True)):
        names = [n for n in raw if ("M" in n) == with_mover]
        for row in range(2):
            ax = axes[row][col]
            for g, name in enumerate(names):
                n_sub = raw[name].shape[0]
                xs = [g * (n_sub + 1) + p for p in range(n_sub)]
                ax.plot(xs, raw[name][:, row], "o", color=f"C{g}")
                ax.plot(xs, corr[name][:, row], "o", mfc="none", color=f"C{g}")
            ticks = [g * 5 + 1.5 for g in range(len(names))]
            ax.set_xticks(ticks, [f"Target {n}" for n in names])
            ax.axhline(0, color="0.6", lw=0.8)
            ax.grid(alpha=0.3)
            ax.set_ylabel(f"{AXES[row]} displacement vs A#1 (m)")
        axes[0][col].set_title("stationary pairs" if not with_mover else "pairs with the mover M")
    fig.suptitle(f"{title}: pair displacement per subpatch A#1..A#4 (filled raw, hollow corrected)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _series(ax, t: pd.DataFrame, tag: str, color: str, label: str) -> None:
    """Theory line and measured markers (filled = detected, x = missed) of one method."""
    floor = 1e-3
    ax.plot(
        t.speed_mps,
        t[f"theory_shift{tag}_m"].clip(lower=floor),
        "-",
        color=color,
        label=f"theory, {label}",
    )
    hit, miss = t[t[f"detected{tag}"]], t[~t[f"detected{tag}"]]
    ax.plot(
        hit.speed_mps,
        hit[f"measured_shift{tag}_m"].clip(lower=floor),
        "o",
        color=color,
        label=f"measured, {label}, detected",
    )
    ax.plot(
        miss.speed_mps,
        miss[f"measured_shift{tag}_m"].clip(lower=floor),
        "x",
        color=color,
        label=f"measured, {label}, missed",
    )
    ax.plot(t.speed_mps, t[f"tolerance{tag}_m"], ":", color=color, label=f"tolerance, {label}")


def plot_ladder(table: pd.DataFrame, paper: dict[float, float], path: Path) -> None:
    """Measured vs theoretical mover displacement against speed, per motion direction."""
    dirs = list(dict.fromkeys(table.direction))
    fig, axes = plt.subplots(1, len(dirs), figsize=(6.5 * len(dirs), 5), squeeze=False)
    for ax, d in zip(axes[0], dirs, strict=True):
        t = table[table.direction == d].sort_values("speed_mps")
        _series(ax, t, "", "C0", "raw (paper)")
        _series(ax, t, "_corrected", "C1", "distortion-corrected")
        ax.plot(
            t.speed_mps,
            t.unaliased_theory_m.clip(lower=1e-3),
            "--",
            color="0.4",
            label="first order v|dc|/V, no aliasing",
        )
        if d == "range":
            ax.plot(list(paper), list(paper.values()), "s", mfc="none", color="k", label="paper")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("mover speed (m/s)")
        ax.set_ylabel("mover displacement beyond the stationary pattern (m)")
        ax.set_title(f"{d} motion")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
