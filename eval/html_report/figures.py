"""The report's figures, drawn from a run's tables as inline SVG (vector, printable, text
kept as text): FROC, precision-recall, pixel ROC and Pd vs SCR of one dataset, one line
per detector (and run) in the detector's own colour
(:func:`~torchsar_eval.colours.detector_colour`). The SVG is deterministic (fixed ids, no
date), so a rebuilt report is identical."""

from __future__ import annotations

import io
import re
from dataclasses import dataclass

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.ticker import FuncFormatter

from torchsar_eval.labels import plain
from torchsar_eval.tables import pooled_pr

__all__ = ["Series", "figure_svg", "first_column"]

_DASHES = ["-", "--", ":", "-."]
SCR_X = ["scr_db", "scr_centre", "scr_center", "scr_mid", "centre", "center", "scr_bin", "bin",
         "scr"]  # fmt: skip
"""Columns that may hold the SCR of a ``scr.csv`` row (the first present is used)."""


@dataclass(frozen=True)
class Series:
    """One line of a figure: a detector of a run."""

    label: str
    detector: str
    colour: str
    dash: str
    summary: pd.Series | None  # its summary row (the operating point), if any


def first_column(df: pd.DataFrame, names: list[str]) -> str | None:
    """The first of ``names`` that ``df`` has."""
    return next((c for c in names if c in df.columns), None)


def _numeric(values: pd.Series) -> np.ndarray:
    """Numbers of a column; interval labels such as ``[0, 5)`` become their midpoints."""
    out = np.array(pd.to_numeric(values, errors="coerce"), dtype=float)
    for i, v in enumerate(values):
        if np.isnan(out[i]) and isinstance(v, str):
            nums = re.findall(r"-?\d+(?:\.\d+)?(?:e-?\d+)?", v)
            if nums:
                out[i] = float(np.mean([float(n) for n in nums[:2]]))
    return out


def _svg(fig: plt.Figure, salt: str, label: str) -> str:
    """The figure as an inline ``<svg>`` element (no XML prolog, no metadata, scalable)."""
    buf = io.StringIO()
    with plt.rc_context({"svg.hashsalt": salt, "svg.fonttype": "none"}):
        fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None, "Format": None,
                                                  "Type": None})  # fmt: skip
    plt.close(fig)
    text = buf.getvalue()
    text = text[text.index("<svg") :]
    text = re.sub(r"<metadata>.*?</metadata>\s*", "", text, flags=re.S)
    head_end = text.index(">")
    head = re.sub(r'\s(width|height)="[^"]*"', "", text[:head_end])
    label = label.replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;")
    head = head.replace("<svg", f'<svg class="fig" role="img" aria-label="{label}"', 1)
    text = head + text[head_end:]
    # ids unique in the page (several figures inline): every id and reference prefixed
    pre = re.sub(r"[^A-Za-z0-9_-]+", "-", salt) + "-"
    text = re.sub(r'\bid="([^"]+)"', lambda m: f'id="{pre}{m.group(1)}"', text)
    text = re.sub(r'href="#([^"]+)"', lambda m: f'href="#{pre}{m.group(1)}"', text)
    return re.sub(r"url\(#([^)]+)\)", lambda m: f"url(#{pre}{m.group(1)})", text)


_PLAIN = FuncFormatter(lambda v, _: f"{v:g}")
"""Tick labels as plain text (``1e-05``, ``0.1``): no math typesetting, quick to draw."""


def _axes(title: str, xlabel: str, ylabel: str) -> tuple[plt.Figure, plt.Axes]:
    fig, ax = plt.subplots(figsize=(4.6, 3.4))
    fig.subplots_adjust(left=0.14, right=0.97, bottom=0.15, top=0.91)
    ax.set(title=plain(title), xlabel=xlabel, ylabel=ylabel)
    ax.grid(True, which="major", alpha=0.3)
    return fig, ax


def _rows(df: pd.DataFrame, s: Series) -> pd.DataFrame:
    return df[df["detector"] == s.detector] if "detector" in df.columns else df.iloc[:0]


def _froc(ax, df: pd.DataFrame, series: list[Series]) -> bool:
    if not {"false_alarms_per_image", "pd_object"} <= set(df.columns):
        return False
    drawn = False
    for s in series:
        d = _rows(df, s)
        if d.empty:
            continue
        ax.step(d["false_alarms_per_image"], d["pd_object"], where="post", color=s.colour,
                linestyle=s.dash, lw=1.4, label=plain(s.label))  # fmt: skip
        op = s.summary
        if op is not None and "false_alarms_per_image" in op and "pd_object" in op:
            ax.plot([op["false_alarms_per_image"]], [op["pd_object"]], "o", color=s.colour,
                    ms=4)  # fmt: skip
        drawn = True
    ax.set_xscale("symlog", linthresh=0.1)
    ax.xaxis.set_major_formatter(_PLAIN)
    ax.set_ylim(0, 1.02)
    return drawn


def _pr(ax, df: pd.DataFrame, series: list[Series]) -> bool:
    if not {"recall", "precision"} <= set(df.columns):
        return False
    df = pooled_pr(df)
    drawn = False
    for s in series:
        d = _rows(df, s)
        if not d.empty:
            ax.plot(d["recall"], d["precision"], color=s.colour, linestyle=s.dash, lw=1.4)
            drawn = True
    ax.set_xlim(0, 1.02)
    ax.set_ylim(0, 1.02)
    return drawn


def _pixel(ax, df: pd.DataFrame, series: list[Series]) -> bool:
    if not {"pfa_pixel", "pd_pixel"} <= set(df.columns):
        return False
    drawn = False
    for s in series:
        d = _rows(df, s)
        d = d[d["pfa_pixel"] > 0]
        if d.empty:
            continue
        ax.plot(d["pfa_pixel"], d["pd_pixel"], color=s.colour, linestyle=s.dash, lw=1.4)
        op = s.summary
        if op is not None and pd.notna(op.get("pfa_pixel")) and op.get("pfa_pixel", 0) > 0:
            ax.plot([op["pfa_pixel"]], [op["pd_pixel"]], "o", color=s.colour, ms=4)
        drawn = True
    ax.set_xscale("log")
    ax.xaxis.set_major_formatter(_PLAIN)
    ax.set_ylim(0, 1.02)
    return drawn


def _scr(ax, df: pd.DataFrame, series: list[Series]) -> bool:
    x_col = first_column(df, SCR_X)
    y_col = first_column(df, ["pd", "pd_object", "recall"])
    if x_col is None or y_col is None:
        return False
    drawn = False
    for s in series:
        d = _rows(df, s)
        if d.empty:
            continue
        x, y = _numeric(d[x_col]), _numeric(d[y_col])
        order = np.argsort(x, kind="stable")
        x, y = x[order], y[order]
        ax.plot(x, y, "o", color=s.colour, linestyle=s.dash, lw=1.4, ms=3)
        if {"pd_lo", "pd_hi"} <= set(d.columns):
            lo, hi = _numeric(d["pd_lo"])[order], _numeric(d["pd_hi"])[order]
            ok = np.isfinite(lo) & np.isfinite(hi) & np.isfinite(y)
            err = [np.maximum(y[ok] - lo[ok], 0.0), np.maximum(hi[ok] - y[ok], 0.0)]
            ax.errorbar(x[ok], y[ok], yerr=err, fmt="none",
                        ecolor=s.colour, elinewidth=0.8, capsize=2, alpha=0.7)  # fmt: skip
        drawn = True
    ax.set_ylim(0, 1.02)
    return drawn


FIGURES = {
    "froc": ("FROC (matching rule)", "false alarms per image", "Pd (object)", "froc", _froc),
    "pr": ("precision-recall, IoU 0.5", "recall", "precision", "pr", _pr),
    "pixel_roc": ("pixel ROC", "Pfa (pixel)", "Pd (pixel)", "pixel_roc", _pixel),
    "scr": ("Pd vs SCR", "SCR (dB)", "Pd (object)", "scr", _scr),
}
"""Each figure: title, axis labels, the table it draws and how."""


def figure_svg(kind: str, table: pd.DataFrame, series: list[Series], salt: str) -> str | None:
    """Figure ``kind`` (a key of :data:`FIGURES`) of ``series`` from ``table`` as inline
    SVG; ``None`` when the table has nothing to draw. ``salt`` makes its element ids unique
    in the page."""
    title, xlabel, ylabel, _, draw = FIGURES[kind]
    if table.empty:
        return None
    fig, ax = _axes(title, xlabel, ylabel)
    if not draw(ax, table, series):
        plt.close(fig)
        return None
    return _svg(fig, f"{salt}-{kind}", title)
