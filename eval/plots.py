"""Plots (matplotlib, headless) in one style: every detector keeps one colour and line style
in every figure, distinct for 20+ detectors; figures are saved as PNG and PDF."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd

__all__ = ["detector_style", "plot_roc", "save", "slug"]

_COLOURS = [plt.cm.tab10(i) for i in range(10)]
_LINES = ["-", "--", "-.", ":"]


def detector_style(i: int) -> dict:
    """Colour and line style of the ``i``-th detector: both change from one detector to the
    next (ten colours x four line styles: 20 distinct pairs before one repeats)."""
    return {"color": _COLOURS[i % 10], "linestyle": _LINES[i % len(_LINES)]}


def slug(name: str) -> str:
    """A file-name-safe form of a dataset name (``folder:../a/b`` -> ``folder_b``)."""
    if ":" in name:
        scheme, _, rest = name.partition(":")
        name = scheme + "_" + Path(rest.split("?")[0].rstrip("/")).name
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def save(fig: plt.Figure, path: Path, rect: tuple[float, ...] = (0, 0, 1, 1)) -> list[str]:
    """Save ``fig`` as ``path`` (PNG) and beside it as PDF; return the file names.
    ``rect`` is the area the axes may fill (room for a figure legend)."""
    fig.tight_layout(rect=rect)
    fig.savefig(path, dpi=110)
    fig.savefig(path.with_suffix(".pdf"))
    plt.close(fig)
    return [path.name, path.with_suffix(".pdf").name]


def _short(name: str) -> str:
    return slug(name) if len(name) > 24 else name


def plot_roc(
    pixel: pd.DataFrame,
    froc: pd.DataFrame,
    pr: pd.DataFrame,
    summary: pd.DataFrame,
    path: Path,
    title: str,
) -> list[str]:
    """Three panels for one dataset: pixel ROC (Pd vs Pfa), FROC (Pd vs false alarms per
    image, matching rule) and precision-recall at IoU 0.5; a filled marker on each curve is
    the detector's design operating point."""
    fig, axes = plt.subplots(1, 3, figsize=(16, 5))
    names = list(dict.fromkeys(summary["detector"]))
    for i, name in enumerate(names):
        st = detector_style(i)
        op = summary[summary["detector"] == name]
        px = pixel[(pixel["detector"] == name) & (pixel["pfa_pixel"] > 0)]
        axes[0].plot(px["pfa_pixel"], px["pd_pixel"], label=name, **st)
        axes[0].plot(op["pfa_pixel"], op["pd_pixel"], "o", color=st["color"])
        fr = froc[froc["detector"] == name]
        axes[1].step(fr["false_alarms_per_image"], fr["pd_object"], where="post", label=name, **st)
        axes[1].plot(op["false_alarms_per_image"], op["pd_object"], "o", color=st["color"])
        p = pr[pr["detector"] == name]
        axes[2].plot(p["recall"], p["precision"], label=name, **st)
    axes[0].set(xscale="log", xlabel="Pfa (pixel)", ylabel="Pd (pixel)", title="pixel ROC")
    axes[1].set(xscale="symlog", xlabel="false alarms per image", ylabel="Pd (object)",
                title="FROC (matching rule)")  # fmt: skip
    axes[2].set(xlabel="recall", ylabel="precision", title="precision-recall, IoU 0.5")
    for ax in axes:
        ax.set_ylim(0, 1.02)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].plot([], [], "o", color="grey", label="design operating point")
    rows = -(-(len(names) + 1) // 7)
    fig.legend(*axes[0].get_legend_handles_labels(), loc="lower center", ncol=7, fontsize=8)
    fig.suptitle(_short(title))
    return save(fig, path, rect=(0, 0.05 * rows + 0.02, 1, 1))
