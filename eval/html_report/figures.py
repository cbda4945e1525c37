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

__all__ = ["Series", "figure_svg", "first_column", "pr_label", "scr_points"]

_DASHES = ["-", "--", ":", "-."]
LEGEND_MAX = 6
"""Most curves whose APs the PR figure lists in its own legend (the page's legend lists
every detector's AP50 too)."""


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


def _svg(fig: plt.Figure, salt: str, label: str) -> str:
    """The figure as an inline ``<svg>`` element (no XML prolog, no metadata, scalable)."""
    buf = io.StringIO()
    with plt.rc_context({"svg.hashsalt": salt, "svg.fonttype": "none"}):
        fig.savefig(
            buf,
            format="svg",
            metadata={"Date": None, "Creator": None, "Format": None, "Type": None},
        )
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


def _id(text: str) -> str:
    """``text`` as a part of an element id."""
    return re.sub(r"[^A-Za-z0-9_-]+", "-", text)


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
        ax.step(
            d["false_alarms_per_image"],
            d["pd_object"],
            where="post",
            color=s.colour,
            linestyle=s.dash,
            lw=1.4,
            label=plain(s.label),
        )
        op = s.summary
        if op is not None and "false_alarms_per_image" in op and "pd_object" in op:
            ax.plot([op["false_alarms_per_image"]], [op["pd_object"]], "o", color=s.colour, ms=4)
        drawn = True
    ax.set_xscale("symlog", linthresh=0.1)
    ax.xaxis.set_major_formatter(_PLAIN)
    ax.set_ylim(0, 1.02)
    return drawn


def pr_label(s: Series) -> str:
    """A PR curve's legend entry: its label and AP (AP50, or the distance rule's AP).

    Examples:
        >>> pr_label(Series("ca", "ca", "#000", "-", pd.Series({"ap50": 0.41234})))
        'ca (AP50 0.412)'
    """
    row = s.summary
    for key, name in (("ap50", "AP50"), ("ap_distance", "AP")):
        v = row.get(key) if row is not None else None
        if v is not None and pd.notna(v):
            return f"{plain(s.label)} ({name} {float(v):.3f})"
    return plain(s.label)


def _pr(ax, df: pd.DataFrame, series: list[Series]) -> bool:
    if not {"recall", "precision"} <= set(df.columns):
        return False
    df = pooled_pr(df)
    drawn = False
    for s in series:
        d = _rows(df, s)
        if not d.empty:
            ax.plot(
                d["recall"],
                d["precision"],
                color=s.colour,
                linestyle=s.dash,
                lw=1.4,
                label=pr_label(s),
            )
            drawn = True
    if drawn and len(ax.lines) <= LEGEND_MAX:  # more: the page's shared legend has the APs
        ax.legend(loc="lower left", fontsize=7, framealpha=0.8)
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


def scr_points(d: pd.DataFrame) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """One detector's rows of ``scr.csv`` as points to draw, per SCR source (``measured``
    first): ``(source, x, pd, (lo, hi))`` with ``x`` each bin's mean SCR of its targets
    (``scr_mean_db``; the bin's middle where that is not finite), in increasing ``x``; bins
    without a Pd (no targets) are left out.

    Examples:
        >>> d = pd.DataFrame({"source": ["measured"] * 2, "scr_lo_db": [5.0, 10.0],
        ...                   "scr_hi_db": [10.0, 15.0], "scr_mean_db": [7.2, float("nan")],
        ...                   "pd": [0.5, 1.0], "pd_lo": [0.2, 0.6], "pd_hi": [0.8, 1.0]})
        >>> [(s, x.tolist(), y.tolist()) for s, x, y, _ in scr_points(d)]
        [('measured', [7.2, 12.5], [0.5, 1.0])]
    """
    if not {"scr_mean_db", "scr_lo_db", "scr_hi_db", "pd"} <= set(d.columns):
        return []  # not a scr.csv of this harness: nothing to place
    d = d.assign(**{c: np.nan for c in ("pd_lo", "pd_hi") if c not in d.columns})
    d = d if "source" in d.columns else d.assign(source="measured")
    out = []
    sources = sorted(set(d["source"]), key=lambda v: (v != "measured", str(v)))
    for source in sources:
        part = d[d["source"] == source]
        x, lo_db, hi_db, y, lo, hi = (
            pd.to_numeric(part[c], errors="coerce").to_numpy(np.float64)
            for c in ("scr_mean_db", "scr_lo_db", "scr_hi_db", "pd", "pd_lo", "pd_hi")
        )
        x = np.where(np.isfinite(x), x, (lo_db + hi_db) / 2)
        ok = np.isfinite(x) & np.isfinite(y)
        order = np.argsort(x[ok], kind="stable")
        out.append((source, x[ok][order], y[ok][order], (lo[ok][order], hi[ok][order])))
    return [p for p in out if p[1].size]


def _scr(ax, df: pd.DataFrame, series: list[Series]) -> bool:
    """Pd at each SCR bin's mean SCR, per detector, with the Wilson intervals: the SCR
    measured on the images (another source, e.g. the simulator's known SCR, only where none
    was measured; every source is in ``scr.csv``)."""
    drawn = False
    for s in series:
        d = _rows(df, s)
        for source, x, y, (lo, hi) in (scr_points(d) if not d.empty else [])[:1]:
            marker = "o" if source == "measured" else "s"
            (line,) = ax.plot(x, y, marker=marker, color=s.colour, linestyle=s.dash, lw=1.4, ms=3)
            line.set_gid(f"scr-line-{_id(s.label)}")  # the page's tests find the points by it
            ok = np.isfinite(lo) & np.isfinite(hi)
            err = [np.maximum(y[ok] - lo[ok], 0.0), np.maximum(hi[ok] - y[ok], 0.0)]
            ax.errorbar(
                x[ok],
                y[ok],
                yerr=err,
                fmt="none",
                ecolor=s.colour,
                elinewidth=0.8,
                capsize=2,
                alpha=0.7,
            )
            drawn = True
    ax.set_ylim(0, 1.02)
    return drawn


FIGURES = {
    "froc": ("FROC (matching rule)", "false alarms per image", "Pd (object)", "froc", _froc),
    "pr": ("precision-recall, IoU 0.5", "recall", "precision", "pr", _pr),
    "pixel_roc": ("pixel ROC", "Pfa (pixel)", "Pd (pixel)", "pixel_roc", _pixel),
    "scr": ("Pd vs SCR (at each bin's mean SCR)", "SCR (dB)", "Pd (object)", "scr", _scr),
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
