"""ROC plots (matplotlib, headless)."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd

__all__ = ["plot_roc", "slug"]


def slug(name: str) -> str:
    """A file-name-safe form of a dataset name (``folder:../a/b`` -> ``folder_b``)."""
    if name.startswith("folder:"):
        name = "folder_" + Path(name[len("folder:") :].split("?")[0].rstrip("/")).name
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def plot_roc(
    pixel: pd.DataFrame, objects: pd.DataFrame, summary: pd.DataFrame, path: Path, title: str
) -> None:
    """Pixel ROC (Pd vs Pfa, log Pfa axis) and object ROC (Pd vs false alarms per image),
    with each detector's design operating point marked."""
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    for i, (name, df) in enumerate(pixel.groupby("detector", sort=False)):
        color = f"C{i % 10}"
        ok = df["pfa_pixel"] > 0
        ax1.plot(df.loc[ok, "pfa_pixel"], df.loc[ok, "pd_pixel"], color=color, label=name)
        op = summary[summary["detector"] == name]
        ax1.plot(op["pfa_pixel"], op["pd_pixel"], "o", color=color)
        ob = objects[objects["detector"] == name]
        ax2.plot(ob["false_alarms_per_image"], ob["pd_object"], ".-", color=color, label=name)
        ax2.plot(op["false_alarms_per_image"], op["pd_object"], "o", color=color)
    ax1.set(
        xscale="log",
        xlabel="Pfa (pixel)",
        ylabel="Pd (pixel)",
        title=f"{title}: pixel ROC",
        ylim=(0, 1.02),
    )
    ax2.set(
        xscale="symlog",
        xlabel="false alarms per image",
        ylabel="Pd (object)",
        title=f"{title}: object ROC",
        ylim=(0, 1.02),
    )
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
