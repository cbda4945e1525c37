"""The report's figures as inline SVG (vector, printable, text kept as text): the run's
panels (:mod:`torchsar_eval.panels`, the same drawers as the PNG/PDF figure) of one
dataset, one curve per detector (and run). The SVG is deterministic (fixed ids, no date),
so a rebuilt report is identical."""

from __future__ import annotations

import io
import re

import pandas as pd

from torchsar_eval.panels import PANELS, Curve, panel_figure
from torchsar_eval.plots import pyplot

__all__ = ["FIGURES", "figure_svg"]

FIGURES = PANELS
"""The page's figures: every panel of :mod:`torchsar_eval.panels`, in this order."""


def _svg(fig, salt: str, label: str) -> str:
    """The figure as an inline ``<svg>`` element (no XML prolog, no metadata, scalable)."""
    plt = pyplot()
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


def figure_svg(kind: str, table: pd.DataFrame, curves: list[Curve], salt: str) -> str | None:
    """Figure ``kind`` (a key of :data:`FIGURES`) of ``curves`` from ``table`` as inline
    SVG; ``None`` when it has no curve to draw. ``salt`` makes its element ids unique in
    the page."""
    fig = panel_figure(kind, table, curves)
    return None if fig is None else _svg(fig, f"{salt}-{kind}", PANELS[kind].title)
