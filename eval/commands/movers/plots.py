"""Figure of ``torchsar-eval movers``: look displacement and velocity estimates vs speed."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd

from torchsar_eval.plots import save

__all__ = ["plot_displacement"]


def plot_displacement(table: pd.DataFrame, path: Path) -> None:
    """Left: look displacement vs speed per direction, with the first-order theory line.
    Right: velocity estimates of the look and focus tests vs the true along-track speed."""
    ladder = table[table.kind == "ladder"]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    for direction, marker in (("along-track", "o"), ("range", "s")):
        part = ladder[ladder.direction == direction].sort_values("speed_mps")
        if part.empty:
            continue
        ax1.plot(part.speed_mps, part.look_shift_m.abs(), marker, label=f"{direction}: measured")
        if direction == "along-track":
            ax1.plot(part.speed_mps, part.theory_look_shift_m, "-", label="theory (2v - v²/V) Δt")
            ax2.plot(part.speed_mps, part.look_velocity_mps, "o", label="look test")
            ax2.plot(part.speed_mps, part.focus_velocity_mps, "x", label="focus test")
            ax2.plot(part.speed_mps, part.speed_mps, "-", color="grey", label="true")
    ax1.set(xscale="log", yscale="symlog", xlabel="mover speed (m/s)",
            ylabel="|azimuth displacement| first to last look (m)")  # fmt: skip
    ax2.set(xscale="log", xlabel="true along-track speed (m/s)", ylabel="estimated speed (m/s)")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    save(fig, path)
