"""The run's curves, drawn once for paper and page: pixel ROC, FROC, precision-recall and
Pd vs SCR panels from a run's tables.

Every figure of a run goes through these drawers, so the PNG/PDF figure of
:func:`plot_roc` and the SVG figures of ``report.html`` show the same points in the same
styles (:func:`~torchsar_eval.plots.detector_style`), with the same log axes
(:func:`~torchsar_eval.plots.log_axis`), operating points, AP legends and "not shown"
notes. Only the sizes differ (:data:`PAPER`, :data:`PAGE`).

matplotlib is imported when a figure is drawn, not when this module is.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from torchsar_eval.labels import plain, short_label
from torchsar_eval.plots import (
    detector_style,
    legend_handles,
    log_axis,
    pyplot,
    save,
    titled,
)
from torchsar_eval.tables import pooled_pr

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "LEGEND_MAX",
    "PAGE",
    "PANELS",
    "PAPER",
    "Curve",
    "Panel",
    "Sizes",
    "ap_note",
    "curves_of",
    "draw_panel",
    "panel_figure",
    "plot_roc",
    "roc_figure",
    "scr_points",
]

LEGEND_MAX = 6
"""Most PR curves listed with their AP in the PR panel's own legend (the figure's or page's
shared legend gives every detector's AP as well)."""


@dataclass(frozen=True)
class Sizes:
    """Line width, curve-marker size, operating-point size and title width (characters)."""

    line: float
    marker: float
    point: float
    title: int


PAPER = Sizes(line=1.5, marker=5, point=9, title=64)
"""The PNG/PDF figure's sizes (three panels on a 16-inch row)."""
PAGE = Sizes(line=1.4, marker=4, point=6, title=46)
"""The report page's sizes (one 4.6-inch panel per figure)."""


@dataclass(frozen=True)
class Curve:
    """One curve of a panel: the rows of a table whose ``detector`` column is ``detector``,
    drawn in the given style and named ``label``; ``summary`` is its summary row (the
    operating point and AP), if any. ``marker`` defaults to the detector's own."""

    label: str
    detector: str
    colour: str
    dash: str
    summary: pd.Series | None = None
    marker: str = field(default="")

    def style(self) -> dict:
        """``{"color", "linestyle", "marker"}`` to draw it with."""
        marker = self.marker or detector_style(self.detector)["marker"]
        return {"color": self.colour, "linestyle": self.dash, "marker": marker}


def curves_of(summary: pd.DataFrame) -> list[Curve]:
    """One curve per detector of a summary table, in each detector's own style."""
    out = []
    for _, row in summary.drop_duplicates("detector").iterrows():
        st = detector_style(str(row["detector"]))
        name = str(row["detector"])
        out.append(Curve(name, name, st["color"], st["linestyle"], row, st["marker"]))
    return out


def ap_note(c: Curve) -> str:
    """A curve's AP as a legend note: ``"AP50 0.412"`` (or the distance rule's ``"AP …"``);
    ``""`` when its summary has none.

    Examples:
        >>> ap_note(Curve("ca", "ca", "#000", "-", pd.Series({"ap50": 0.41234})))
        'AP50 0.412'
    """
    row = c.summary
    for key, name in (("ap50", "AP50"), ("ap_distance", "AP")):
        v = row.get(key) if row is not None else None
        if v is not None and pd.notna(v):
            return f"{name} {float(v):.3f}"
    return ""


def _ap(c: Curve) -> float | None:
    row = c.summary
    for key in ("ap50", "ap_distance"):
        v = row.get(key) if row is not None else None
        if v is not None and pd.notna(v):
            return float(v)
    return None


def _rows(df: pd.DataFrame, c: Curve) -> pd.DataFrame:
    return df[df["detector"] == c.detector] if "detector" in df.columns else df.iloc[:0]


def _op(c: Curve, x: str, y: str) -> tuple[float, float] | None:
    """The curve's operating point ``(x, y)`` from its summary row, if it has both."""
    row = c.summary
    if row is None or x not in row or y not in row:
        return None
    px, py = pd.to_numeric(pd.Series([row[x], row[y]]), errors="coerce")
    return (float(px), float(py)) if np.isfinite(px) and np.isfinite(py) else None


def _line(ax: Axes, c: Curve, size: Sizes, x, y, **kw) -> None:
    ax.plot(
        x,
        y,
        **c.style(),
        lw=size.line,
        markevery=0.1,
        markersize=size.marker,
        label=kw.pop("label", plain(c.label)),
        **kw,
    )


def _point(ax: Axes, c: Curve, size: Sizes, xy: tuple[float, float]) -> None:
    ax.plot(
        [xy[0]],
        [xy[1]],
        color=c.colour,
        marker=c.style()["marker"],
        markersize=size.point,
        markeredgecolor="black",
        linestyle="none",
        zorder=3,
    )


# -- the panels --------------------------------------------------------------------------
# Each draws its curves on ``ax`` and returns the detectors it leaves out, with why.


def _pixel(ax: Axes, df: pd.DataFrame, curves: list[Curve], size: Sizes) -> dict[str, str]:
    left = {}
    has = {"pfa_pixel", "pd_pixel"} <= set(df.columns)
    xs: list[float] = []
    for c in curves:
        every = _rows(df, c) if has else df.iloc[:0]
        d = every[every["pfa_pixel"] > 0] if has else every
        if d.empty:
            left[c.label] = "no pixel mask" if every.empty else "Pfa = 0 at every threshold"
            continue
        _line(ax, c, size, d["pfa_pixel"], d["pd_pixel"])
        xs += d["pfa_pixel"].tolist()
        op = _op(c, "pfa_pixel", "pd_pixel")
        if op is not None and op[0] > 0:
            _point(ax, c, size, op)
    log_axis(ax, "x", xs)
    return left


def _froc(ax: Axes, df: pd.DataFrame, curves: list[Curve], size: Sizes) -> dict[str, str]:
    left = {}
    has = {"false_alarms_per_image", "pd_object"} <= set(df.columns)
    xs: list[float] = []
    for c in curves:
        d = _rows(df, c) if has else df.iloc[:0]
        if d.empty:
            left[c.label] = "no object scored"
            continue
        _line(ax, c, size, d["false_alarms_per_image"], d["pd_object"], drawstyle="steps-post")
        xs += d["false_alarms_per_image"].tolist()
        op = _op(c, "false_alarms_per_image", "pd_object")
        if op is not None:
            _point(ax, c, size, op)
            xs.append(op[0])
    log_axis(ax, "x", xs)
    return left


def _pr(ax: Axes, df: pd.DataFrame, curves: list[Curve], size: Sizes) -> dict[str, str]:
    left = {}
    df = pooled_pr(df) if {"recall", "precision"} <= set(df.columns) else df.iloc[:0]
    for c in curves:
        d = _rows(df, c)
        ap = _ap(c)
        if ap == 0:
            left[c.label] = "AP50 = 0" if ap_note(c).startswith("AP50") else "AP = 0"
        elif d.empty:
            left[c.label] = "no PR curve"
        else:
            note = ap_note(c)
            label = plain(c.label) + (f" ({note})" if note else "")
            _line(ax, c, size, d["recall"], d["precision"], label=label)
    if 0 < len(ax.lines) <= LEGEND_MAX:  # a few curves: each one's AP beside it
        ax.legend(loc="lower left", fontsize=7, framealpha=0.8)
    ax.set_xlim(0, 1.02)
    return left


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


def _gid(text: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "_-" else "-" for ch in text)


def _scr(ax: Axes, df: pd.DataFrame, curves: list[Curve], size: Sizes) -> dict[str, str]:
    """Pd at each SCR bin's mean SCR, per detector, with the Wilson intervals: the SCR
    measured on the images (another source, e.g. the simulator's known SCR, drawn with
    hollow markers, only where none was measured; every source is in ``scr.csv``). Each
    line's gid is ``scr-line-<label>``."""
    left = {}
    for c in curves:
        d = _rows(df, c)
        points = scr_points(d) if not d.empty else []
        if not points:
            left[c.label] = "no target in an SCR bin"
            continue
        source, x, y, (lo, hi) = points[0]
        st = c.style()
        hollow = {} if source == "measured" else {"markerfacecolor": "none"}
        (line,) = ax.plot(
            x, y, **st, lw=size.line, markersize=size.marker, label=plain(c.label), **hollow
        )
        line.set_gid(f"scr-line-{_gid(c.label)}")  # the page's tests find the points by it
        ok = np.isfinite(lo) & np.isfinite(hi)
        err = [np.maximum(y[ok] - lo[ok], 0.0), np.maximum(hi[ok] - y[ok], 0.0)]
        ax.errorbar(
            x[ok],
            y[ok],
            yerr=err,
            fmt="none",
            ecolor=c.colour,
            elinewidth=0.8,
            capsize=2,
            alpha=0.7,
        )
    return left


@dataclass(frozen=True)
class Panel:
    """A panel: its title, axis labels, the run table it draws and its drawer."""

    title: str
    xlabel: str
    ylabel: str
    table: str
    draw: Callable[[Axes, pd.DataFrame, list[Curve], Sizes], dict[str, str]]


PANELS = {
    "pixel_roc": Panel("pixel ROC", "Pfa (pixel)", "Pd (pixel)", "pixel_roc", _pixel),
    "froc": Panel("FROC (matching rule)", "false alarms per image", "Pd (object)", "froc", _froc),
    "pr": Panel("precision-recall, IoU 0.5", "recall", "precision", "pr", _pr),
    "scr": Panel("Pd vs SCR (at each bin's mean SCR)", "SCR (dB)", "Pd (object)", "scr", _scr),
}
"""Every panel of a run's figures, by kind."""


def draw_panel(
    ax: Axes, kind: str, table: pd.DataFrame, curves: list[Curve], size: Sizes = PAPER
) -> dict[str, str]:
    """Draw panel ``kind`` (a key of :data:`PANELS`) of ``curves`` from ``table`` on
    ``ax``: the curves, their operating points, axes, grid and a title that names the
    detectors left out and why. Returns those left out (``{label: why}``)."""
    panel = PANELS[kind]
    left = panel.draw(ax, table, curves, size)
    ax.set(xlabel=panel.xlabel, ylabel=panel.ylabel)
    ax.set_ylim(0, 1.02)
    ax.grid(True, which="major", alpha=0.3)
    titled(ax, panel.title, left, width=size.title)
    return left


def panel_figure(kind: str, table: pd.DataFrame, curves: list[Curve]) -> Figure | None:
    """Panel ``kind`` alone, at the page's size; ``None`` when it draws no curve."""
    if table.empty:
        return None
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(4.6, 3.4))
    left = draw_panel(ax, kind, table, curves, PAGE)
    if len(left) == len(curves):
        plt.close(fig)
        return None
    fig.tight_layout(pad=0.4)
    return fig


# -- the run's ROC figure (PNG and PDF) --------------------------------------------------

LEGEND_COLUMNS = 7


def roc_figure(
    pixel: pd.DataFrame,
    froc: pd.DataFrame,
    pr: pd.DataFrame,
    summary: pd.DataFrame,
    title: str,
) -> Figure:
    """The three panels of :func:`plot_roc` as a figure."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.2))
    curves = curves_of(summary)
    for ax, kind, table in zip(axes, ("pixel_roc", "froc", "pr"), (pixel, froc, pr), strict=True):
        draw_panel(ax, kind, table, curves, PAPER)
    drawn_pr = {line.get_label().split(" (")[0] for line in axes[2].lines}
    notes = {c.label: ap_note(c) for c in curves if plain(c.label) in drawn_pr and ap_note(c)}
    # matplotlib on the first figure (see the module's docstring)
    from matplotlib.lines import Line2D

    handles = legend_handles([c.label for c in curves], notes)  # every curve's AP too
    handles.append(
        Line2D(
            [],
            [],
            color="grey",
            marker="o",
            markeredgecolor="black",
            linestyle="none",
            label="design operating point",
        )
    )
    fig.legend(handles=handles, loc="lower center", ncol=LEGEND_COLUMNS, fontsize=8)
    fig.suptitle(plain(short_label(title)))
    return fig


def plot_roc(
    pixel: pd.DataFrame,
    froc: pd.DataFrame,
    pr: pd.DataFrame,
    summary: pd.DataFrame,
    path: Path,
    title: str,
) -> list[str]:
    """Three panels for one dataset: pixel ROC (Pd vs Pfa), FROC (Pd vs false alarms per
    image, matching rule) and precision-recall at IoU 0.5 (detectors with AP50 > 0); a
    large marker on each curve is the detector's design operating point. Each panel names
    the detectors it leaves out and why. The report page draws the same panels."""
    fig = roc_figure(pixel, froc, pr, summary, title)
    entries = len(dict.fromkeys(summary["detector"])) + 1
    rows = -(-entries // LEGEND_COLUMNS)
    return save(fig, path, rect=(0, 0.05 * rows + 0.02, 1, 1))
