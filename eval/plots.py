"""Plots (matplotlib, headless) in one style, fit for a paper: the styles, axes and files
every figure of the harness uses (the run's curves are drawn by
:mod:`torchsar_eval.panels`, on paper and page alike).

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
from torchsar_eval.labels import plain
from torchsar_eval.names import slug

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "STYLES",
    "detector_style",
    "legend_handles",
    "log_axis",
    "log_ticks",
    "not_shown",
    "pyplot",
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
