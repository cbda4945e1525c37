"""Figure of ``torchsar-eval movers``: look displacements and estimates vs speed."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from torchsar_eval.plots import log_axis, pyplot, save

__all__ = ["plot_displacement"]


def plot_displacement(table: pd.DataFrame, path: Path) -> None:
    """Left: azimuth look displacement vs speed per direction, with the first-order theory.
    Middle: range movers' walk between looks (m/s) vs the fold theory ``-k lambda PRF / 2``,
    folds found marked. Right: velocity estimates of the look and focus tests vs the true
    along-track speed."""
    ladder = table[table.kind == "ladder"]
    fig, (ax1, ax2, ax3) = pyplot().subplots(1, 3, figsize=(15, 4.5))
    for direction, marker in (("along-track", "o"), ("range", "s")):
        part = ladder[ladder.direction == direction].sort_values("speed_mps")
        if part.empty:
            continue
        ax1.plot(part.speed_mps, part.look_shift_m.abs(), marker, label=f"{direction}: measured")
        if direction == "along-track":
            ax1.plot(part.speed_mps, part.theory_look_shift_m, "-", label="theory (2v - v²/V) Δt")
            ax3.plot(part.speed_mps, part.look_velocity_mps, "o", label="look test")
            ax3.plot(part.speed_mps, part.focus_velocity_mps, "x", label="focus test")
            ax3.plot(part.speed_mps, part.speed_mps, "-", color="grey", label="true")
        else:
            _plot_walk(ax2, part)
    speeds = ladder.speed_mps
    log_axis(ax1, "x", speeds)
    theory = ladder[ladder.direction == "along-track"].theory_look_shift_m.dropna()
    log_axis(ax1, "y", [*ladder.look_shift_m.abs().dropna(), *theory])
    log_axis(ax3, "x", speeds)
    ax1.set(xlabel="mover speed (m/s)", ylabel="|azimuth displacement| first to last look (m)")
    ax2.set(xlabel="radial speed (m/s)", ylabel="range walk between looks (m/s)")
    ax3.set(xlabel="true along-track speed (m/s)", ylabel="estimated speed (m/s)")
    for ax in (ax1, ax2, ax3):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    save(fig, path)


def _plot_walk(ax, part: pd.DataFrame) -> None:
    """Measured walk of each range mover, the fold law, and the fold each was flagged with."""
    ax.plot(part.speed_mps, part.walk_mps, "s", label="measured")
    ax.step(
        part.speed_mps,
        part.theory_walk_mps,
        "-",
        where="mid",
        color="grey",
        label="theory -k λ PRF / 2",
    )
    found = part[part.radial_detected]
    ax.plot(found.speed_mps, found.walk_mps, "o", mfc="none", ms=12, label="flagged radial")
    for row in found.itertuples():
        ax.annotate(
            f"k={row.fold:.0f}",
            (row.speed_mps, row.walk_mps),
            fontsize=7,
            textcoords="offset points",
            xytext=(6, -10),
        )
