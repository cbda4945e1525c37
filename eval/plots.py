"""Plots (matplotlib, headless) in one style, fit for a paper.

- Every detector keeps its colour, line style and marker in every figure, whatever the other
  detectors of the run (:func:`detector_style`, keyed by name: the report's colours, and a
  distinct marker per built-in so curves stay apart for colour-blind readers and in grey).
- Log axes carry enough labelled ticks to read a value: 1-2-5 per decade (or finer) when
  the data span few decades, and a symmetric-log axis when 0 is among the values
  (:func:`log_axis`).
- A panel that leaves a detector out says which and why (:func:`not_shown`).

matplotlib is imported when a figure is drawn, not when this module is.
"""

from __future__ import annotations

import hashlib
import math
import textwrap
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from torchsar_eval.colours import detector_colour, detector_dash
from torchsar_eval.labels import plain, short_label
from torchsar_eval.names import slug
from torchsar_eval.tables import pooled_pr

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

LEGEND_MAX = 6
"""Most PR curves listed with their AP in the PR panel's own legend (the figure's legend
gives every detector's AP50 as well)."""

__all__ = [
    "STYLES",
    "detector_style",
    "legend_handles",
    "log_axis",
    "log_ticks",
    "not_shown",
    "plot_roc",
    "pyplot",
    "roc_figure",
    "save",
    "slug",
    "titled",
]

MARKERS: dict[str, str] = {
    "ca": "o",
    "two_parameter": "s",
    "go": "^",
    "so": "v",
    "os": "D",
    "vi": "P",
    "ac": "X",
    "lognormal": "<",
    "weibull": ">",
    "gamma": "h",
    "k": "p",
    "g0": "*",
    "region": "d",
    "region-paper": "H",
}
"""The built-in detectors' markers: pairwise distinct, so curves stay apart in grey print
and for colour-blind readers even where colours are close."""
_OTHER_MARKERS = ["o", "s", "^", "v", "D", "P", "X", "<", ">", "h", "p", "*", "d", "H", "8"]
STYLES: dict[str, tuple[str, str, str]] = {
    n: (detector_colour(n), detector_dash(n), m) for n, m in MARKERS.items()
}
"""(colour, line style, marker) of the built-in detectors: the colours and line styles of
:mod:`torchsar_eval.colours` (the report's), these markers."""


def detector_style(name: str) -> dict:
    """``{"color", "linestyle", "marker"}`` of a detector, by name: the same in every figure
    (PNG, PDF and ``report.html``) and run. The built-ins have fixed distinct styles
    (:data:`STYLES`); any other name gets one from a hash of the name (stable across
    processes), never a built-in's colour.

    Examples:
        >>> detector_style("ca")
        {'color': '#1f77b4', 'linestyle': '-', 'marker': 'o'}
        >>> detector_style("my-cnn") == detector_style("my-cnn")
        True
    """
    marker = MARKERS.get(name)
    if marker is None:
        marker = _OTHER_MARKERS[
            int.from_bytes(hashlib.sha256(name.encode()).digest()[:8], "big") % len(_OTHER_MARKERS)
        ]
    color, line = detector_colour(name), detector_dash(name)
    return {"color": color, "linestyle": line, "marker": marker}


def pyplot():
    """``matplotlib.pyplot`` on the headless Agg backend (imported on first use)."""
    # matplotlib on the first figure (see the module's docstring)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # after the backend is chosen

    return plt


def legend_handles(names: Iterable[str], notes: dict[str, str] | None = None) -> list:
    """One legend entry per detector in its style (whether or not a panel shows it), with its
    ``notes`` entry in brackets (e.g. its AP50)."""
    # matplotlib on the first figure (see the module's docstring)
    from matplotlib.lines import Line2D

    notes = notes or {}
    return [
        Line2D(
            [], [], label=plain(n) + (f" ({notes[n]})" if n in notes else ""), **detector_style(n)
        )
        for n in names
    ]


def not_shown(left_out: Mapping[str, str]) -> str:
    """The note of a panel that leaves detectors out, grouped by reason (``""`` if none).

    Examples:
        >>> not_shown({"lognormal": "AP50 = 0", "g0": "AP50 = 0", "x": "no objects"})
        'not shown: lognormal, g0 (AP50 = 0); x (no objects)'
    """
    if not left_out:
        return ""
    reasons: dict[str, list[str]] = {}
    for name, why in left_out.items():
        reasons.setdefault(why, []).append(name)
    return "not shown: " + "; ".join(f"{', '.join(n)} ({why})" for why, n in reasons.items())


def titled(ax: Axes, title: str, left_out: Mapping[str, str], width: int = 64) -> None:
    """Set a panel's title, with the :func:`not_shown` note below it (wrapped)."""

    note = textwrap.fill(not_shown(left_out), width, break_long_words=False)
    ax.set_title(plain(title if not note else f"{title}\n{note}"), fontsize=10 if not note else 9)


# -- log axes ---------------------------------------------------------------------------

_SUBS = [(1.0,), (1.0, 2.0, 5.0), (1.0, 2.0, 3.0, 5.0), tuple(float(m) for m in range(1, 10))]
MAX_DECADE_TICKS = 8


def _candidates(lo: float, hi: float, subs: Sequence[float]) -> list[float]:
    out = []
    for k in range(math.floor(math.log10(lo)), math.ceil(math.log10(hi)) + 1):
        for m in subs:
            t = float(f"{m * 10.0**k:.12g}")
            if lo * (1 - 1e-9) <= t <= hi * (1 + 1e-9):
                out.append(t)
    return out


def log_ticks(lo: float, hi: float, least: int = 3) -> list[float]:
    """Labelled tick positions for a log axis over ``[lo, hi]`` (both > 0): the decades
    when the range spans two or more (every second or third one when they are many), else
    1-2-5 per decade, or finer where that leaves fewer than ``least`` in the range.

    Examples:
        >>> log_ticks(2, 6)
        [2.0, 3.0, 5.0]
        >>> log_ticks(0.02, 1)
        [0.02, 0.05, 0.1, 0.2, 0.5, 1.0]
        >>> log_ticks(1e-6, 1)
        [1e-06, 1e-05, 0.0001, 0.001, 0.01, 0.1, 1.0]
    """
    if not (0 < lo <= hi and math.isfinite(hi)):
        raise ValueError(f"log_ticks needs 0 < lo <= hi, got {lo}, {hi}")
    ticks: list[float] = []
    first = 0 if math.log10(hi / lo) >= 2 else 1
    for subs in _SUBS[first:]:
        ticks = _candidates(lo, hi, subs)
        if len(ticks) >= least:
            break
    if len(ticks) > MAX_DECADE_TICKS:
        step = math.ceil(len(ticks) / MAX_DECADE_TICKS)
        ticks = ticks[::step]
    return ticks


def _tick_label(v: float) -> str:
    if v == 0:
        return "0"
    if 1e-3 <= abs(v) < 1e4:
        return f"{v:g}"
    k = math.floor(math.log10(abs(v)))
    m = v / 10.0**k
    return rf"$10^{{{k}}}$" if abs(m - 1) < 1e-9 else rf"${m:g}\times10^{{{k}}}$"


def _nice_below(v: float) -> float:
    """The largest 1, 2 or 5 x 10^k that is <= ``v`` (> 0)."""
    k = math.floor(math.log10(v))
    return max(m * 10.0**k for m in (1, 2, 5) if m * 10.0**k <= v * (1 + 1e-12))


def log_axis(ax: Axes, which: str, values: Iterable[float], least: int = 3) -> None:
    """Make the ``x`` or ``y`` axis of ``ax`` logarithmic with readable ticks for
    ``values``: a log axis labelled by :func:`log_ticks`, or a symmetric-log axis (linear
    near 0) when 0 is among the values, so no point is dropped."""
    # matplotlib on the first figure (see the module's docstring)
    from matplotlib.ticker import FixedLocator, FuncFormatter, LogLocator, NullFormatter

    vals = [float(v) for v in values if v == v and math.isfinite(float(v))]
    pos = [v for v in vals if v > 0]
    axis = ax.xaxis if which == "x" else ax.yaxis
    set_scale = ax.set_xscale if which == "x" else ax.set_yscale
    if not pos:
        return
    lo, hi = min(pos), max(pos)
    if any(v <= 0 for v in vals):
        linthresh = _nice_below(lo)
        set_scale("symlog", linthresh=linthresh, linscale=0.5)
        ticks = [0.0, *log_ticks(linthresh, max(hi, linthresh), max(least - 1, 1))]
        axis.set_minor_locator(FixedLocator([]))
    else:
        set_scale("log")
        ticks = log_ticks(lo, hi, least) if hi > lo else [lo]
        axis.set_minor_locator(LogLocator(base=10, subs="auto"))
    axis.set_major_locator(FixedLocator(ticks))
    axis.set_major_formatter(FuncFormatter(lambda v, _: _tick_label(v)))
    axis.set_minor_formatter(NullFormatter())


# -- files ------------------------------------------------------------------------------


def save(fig: Figure, path: Path, rect: tuple[float, ...] = (0, 0, 1, 1)) -> list[str]:
    """Save ``fig`` as ``path`` (PNG) and beside it as PDF; return the file names.
    ``rect`` is the area the axes may fill (room for a figure legend)."""
    plt = pyplot()
    fig.tight_layout(rect=rect)
    fig.savefig(path, dpi=110)
    fig.savefig(path.with_suffix(".pdf"))
    plt.close(fig)
    return [path.name, path.with_suffix(".pdf").name]


# -- the run's ROC figure ---------------------------------------------------------------

LEGEND_COLUMNS = 7


def _ap50(summary: pd.DataFrame, name: str) -> float:
    if "ap50" not in summary:
        return float("nan")
    values = summary.loc[summary["detector"] == name, "ap50"]
    return float(values.iloc[0]) if len(values) else float("nan")


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
    names = list(dict.fromkeys(summary["detector"]))
    left: list[dict[str, str]] = [{}, {}, {}]
    aps: dict[str, str] = {}
    marks = {"markevery": 0.1, "markersize": 5}
    for name in names:
        st = detector_style(name)
        op = summary[summary["detector"] == name]
        point = {
            "color": st["color"],
            "marker": st["marker"],
            "markersize": 9,
            "markeredgecolor": "black",
            "linestyle": "none",
            "zorder": 3,
        }
        px_all = pixel[pixel["detector"] == name]
        px = px_all[px_all["pfa_pixel"] > 0]
        if px.empty:
            left[0][name] = "no pixel mask" if px_all.empty else "Pfa = 0 at every threshold"
        else:
            axes[0].plot(px["pfa_pixel"], px["pd_pixel"], label=plain(name), **st, **marks)
            shown_op = op[op["pfa_pixel"] > 0]
            axes[0].plot(shown_op["pfa_pixel"], shown_op["pd_pixel"], **point)
        fr = froc[froc["detector"] == name]
        if fr.empty:
            left[1][name] = "no object scored"
        else:
            axes[1].step(
                fr["false_alarms_per_image"],
                fr["pd_object"],
                where="post",
                label=plain(name),
                **st,
                **marks,
            )
            axes[1].plot(op["false_alarms_per_image"], op["pd_object"], **point)
        p = pooled_pr(pr[pr["detector"] == name])
        ap = _ap50(summary, name)
        if p.empty or not ap > 0:
            left[2][name] = "AP50 = 0" if ap == 0 else "no AP50"
        else:
            axes[2].plot(
                p["recall"], p["precision"], label=f"{plain(name)} (AP50 {ap:.3f})", **st, **marks
            )
            aps[name] = f"AP50 {ap:.3f}"
    log_axis(axes[0], "x", pixel.loc[pixel["pfa_pixel"] > 0, "pfa_pixel"])
    log_axis(axes[1], "x", [*froc["false_alarms_per_image"], *summary["false_alarms_per_image"]])
    axes[0].set(xlabel="Pfa (pixel)", ylabel="Pd (pixel)")
    axes[1].set(xlabel="false alarms per image", ylabel="Pd (object)")
    axes[2].set(xlabel="recall", ylabel="precision", xlim=(0, 1.02))
    if 0 < len(axes[2].lines) <= LEGEND_MAX:  # a few curves: each one's AP beside it
        axes[2].legend(loc="lower left", fontsize=7, framealpha=0.8)
    panel_titles = ["pixel ROC", "FROC (matching rule)", "precision-recall, IoU 0.5"]
    for ax, panel, out in zip(axes, panel_titles, left, strict=True):
        ax.set_ylim(0, 1.02)
        ax.grid(True, which="major", alpha=0.3)
        titled(ax, panel, out)
    # matplotlib on the first figure (see the module's docstring)
    from matplotlib.lines import Line2D

    handles = legend_handles(names, aps)  # every curve's AP50 in the figure's legend
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
    the detectors it leaves out and why."""
    fig = roc_figure(pixel, froc, pr, summary, title)
    entries = len(dict.fromkeys(summary["detector"])) + 1
    rows = -(-entries // LEGEND_COLUMNS)
    return save(fig, path, rect=(0, 0.05 * rows + 0.02, 1, 1))
