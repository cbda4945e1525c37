"""Figures fit for a paper: styles keyed by detector name, readable log axes, panels that
name what they leave out, and the command figures (dB chips, GOTCHA grid, aligned autofocus
images)."""

from __future__ import annotations

import itertools
import math
import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
import torch

from torchsar_eval.colours import detector_colour, detector_dash
from torchsar_eval.panels import curves_of, panel_figure, roc_figure
from torchsar_eval.plots import (
    STYLES,
    detector_style,
    log_axis,
    log_ticks,
    not_shown,
    pyplot,
)
from torchsar_eval.registry import BUILTIN

plt = pyplot()


def _key(style: dict) -> tuple:
    line = style["linestyle"]
    return style["color"], str(line), style["marker"]


def test_the_13_builtins_have_pairwise_distinct_styles():
    styles = {n: _key(detector_style(n)) for n in BUILTIN}
    assert len(styles) == 13
    for a, b in itertools.combinations(BUILTIN, 2):
        sa, sb = styles[a], styles[b]
        assert sa[:2] != sb[:2], f"{a} and {b} share colour and line style"
        assert sa[2] != sb[2], f"{a} and {b} share a marker"


def test_plots_and_the_report_draw_a_detector_alike():
    """The PNG/PDF plots and report.html take a detector's colour and line style from one
    place; every built-in has its own colour and marker."""
    for n in [*BUILTIN, "region-paper", "my-cnn"]:
        st = detector_style(n)
        assert (st["color"], st["linestyle"]) == (detector_colour(n), detector_dash(n))
    assert len({STYLES[n][0] for n in BUILTIN}) == len(BUILTIN)
    assert len({STYLES[n][2] for n in BUILTIN}) == len(BUILTIN)


@pytest.mark.integration  # a fresh process
def test_unknown_names_get_a_stable_style_unlike_any_builtin():
    names = ["my-cnn", "yolo-sar", "a", "mine=pkg.mod:Det", "ünïcode"]
    code = (
        "from torchsar_eval.plots import detector_style\n"
        f"print(repr([detector_style(n) for n in {names!r}]))"
    )
    here = repr([detector_style(n) for n in names])
    for seed in ("12345",):  # another process, another string-hash seed
        env = {**os.environ, "PYTHONHASHSEED": seed}
        out = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
        )
        assert out.stdout.strip() == here
    builtin = {(c, line) for c, line, _ in STYLES.values()}
    for n in names:
        s = detector_style(n)
        assert (s["color"], s["linestyle"]) not in builtin
        assert s["color"] not in {STYLES[b][0] for b in BUILTIN}


def _tables(names: list[str], ap50: dict[str, float] | None = None):
    """Small tables of the shape the run writes, one curve per detector."""
    rng = np.random.default_rng(0)
    pixel, froc, pr, summary = [], [], [], []
    for k, n in enumerate(names):
        pfa = np.sort(rng.uniform(1e-4, 1e-1, 6))
        pixel += [{"detector": n, "pfa_pixel": f, "pd_pixel": min(1, 0.2 + 5 * f)} for f in pfa]
        fa = [0.0, 2.0, 3.5, 6.0]
        froc += [
            {"detector": n, "false_alarms_per_image": f, "pd_object": 0.1 * k % 1 + f / 10}
            for f in fa
        ]
        pr += [{"detector": n, "recall": r, "precision": 1 - r / 2} for r in (0.1, 0.5, 0.9)]
        summary.append(
            {
                "detector": n,
                "pfa_pixel": pfa[2],
                "pd_pixel": 0.5,
                "false_alarms_per_image": 2.0,
                "pd_object": 0.5,
                "ap50": (ap50 or {}).get(n, 0.6),
            }
        )
    return [pd.DataFrame(t) for t in (pixel, froc, pr, summary)]


def _colours(fig) -> dict[str, tuple]:
    out = {}
    for ax in fig.axes:
        for line in ax.get_lines():
            if not line.get_label().startswith("_"):
                out.setdefault(line.get_label(), set()).add(line.get_color())
    return {k: tuple(sorted(v)) for k, v in out.items()}


def test_a_detector_keeps_its_colour_whatever_the_other_detectors():
    first = roc_figure(*_tables(["ca", "region", "go", "mine"]), "run 1")
    second = roc_figure(*_tables(["region", "k", "mine", "ca", "os", "so"]), "run 2")
    a, b = _colours(first), _colours(second)
    plt.close("all")
    for name in ("ca", "region", "mine"):
        assert a[name] == b[name] == (detector_style(name)["color"],)
    assert a["region"] != a["go"]


def _labelled(ax, which: str, lo: float, hi: float) -> list[str]:
    ax.figure.canvas.draw()
    axis = ax.xaxis if which == "x" else ax.yaxis
    ticks = axis.get_majorticklocs()
    labels = [t.get_text() for t in axis.get_majorticklabels()]
    return [s for t, s in zip(ticks, labels, strict=True) if s and lo <= t <= hi]


def test_froc_and_pixel_roc_axes_have_three_labelled_ticks_in_the_data_range():
    """Chips: points at 2-6 false alarms per image and 0; pixel Pfa within 1.5 decades."""
    fig = roc_figure(*_tables(["ca", "so"]), "chips")
    pixel_roc, froc = fig.axes[0], fig.axes[1]
    assert len(_labelled(froc, "x", 0, 6)) >= 3
    assert len(_labelled(froc, "x", 2, 6)) >= 2  # labels among the points themselves
    assert len(_labelled(pixel_roc, "x", 1e-4, 1e-1)) >= 3
    plt.close(fig)


@pytest.mark.parametrize("with_zero", [False, True])
def test_log_axis_labels_three_ticks_over_any_range_of_a_factor_4_or_more(with_zero):
    rng = np.random.default_rng(1)
    for _ in range(15):
        lo = 10 ** rng.uniform(-9, 3)
        hi = lo * 10 ** rng.uniform(math.log10(4), 8)
        fig, ax = plt.subplots()
        values = [lo, hi, *([0.0] if with_zero else [])]
        ax.plot(values, [0.5] * len(values), "o")
        log_axis(ax, "x", values)
        assert len(_labelled(ax, "x", 0 if with_zero else lo, hi)) >= 3, (lo, hi)
        plt.close(fig)


def test_log_ticks_are_decades_over_many_decades_and_1_2_5_over_few():
    assert log_ticks(1e-6, 1) == [10.0**k for k in range(-6, 1)]
    assert log_ticks(0.1, 5) == [0.1, 0.2, 0.5, 1, 2, 5]
    assert len(log_ticks(1e-30, 1)) <= 8


def test_the_pr_panel_names_the_detectors_it_leaves_out():
    names = ["ca", "lognormal", "g0", "region"]
    fig = roc_figure(*_tables(names, ap50={"lognormal": 0.0, "g0": 0.0}), "chips")
    pr = fig.axes[2]
    shown = {line.get_label().split(" (")[0] for line in pr.get_lines()}
    assert {"ca", "region"} <= shown and not {"lognormal", "g0"} & shown
    ap = {t.get_text() for t in pr.get_legend().get_texts()}  # each curve with its AP50
    assert ap == {"ca (AP50 0.600)", "region (AP50 0.600)"}
    assert "not shown: lognormal, g0 (AP50 = 0)" in " ".join(pr.get_title().split())
    assert "not shown" not in fig.axes[0].get_title()  # nothing left out there
    legend = {t.get_text().split(" (")[0] for t in fig.legends[0].get_texts()}
    assert set(names) <= legend  # the legend still names every detector
    with_ap = {t.get_text() for t in fig.legends[0].get_texts()}
    assert {"ca (AP50 0.600)", "region (AP50 0.600)"} <= with_ap  # and each drawn curve's AP
    plt.close(fig)


def _drawn(ax) -> list[tuple]:
    return [
        (
            ln.get_label(),
            *(list(map(float, v)) for v in ln.get_data()),
            ln.get_color(),
            ln.get_linestyle(),
            ln.get_marker(),
            ln.get_markeredgecolor(),
        )
        for ln in ax.lines
    ]


def test_the_page_and_the_paper_figure_draw_the_same_curves():
    """One plotting stack: each panel of report.html shows the same lines (points, colour,
    line style, marker, operating point), axis scale and left-out note as the PNG/PDF."""
    pixel, froc, pr, summary = _tables(["ca", "go", "lognormal", "mine"], ap50={"lognormal": 0})
    paper = roc_figure(pixel, froc, pr, summary, "run")
    curves = curves_of(summary)
    for ax, kind, table in zip(
        paper.axes, ["pixel_roc", "froc", "pr"], [pixel, froc, pr], strict=True
    ):
        page = panel_figure(kind, table, curves)
        (pax,) = page.axes
        assert _drawn(pax) == _drawn(ax) and len(ax.lines) >= 3, kind
        assert pax.get_xscale() == ax.get_xscale()
        assert list(pax.get_xticks()) == list(ax.get_xticks())
        assert " ".join(pax.get_title().split()) == " ".join(ax.get_title().split())
        plt.close(page)
    assert "not shown: lognormal (AP50 = 0)" in " ".join(paper.axes[2].get_title().split())
    plt.close(paper)


def test_a_panel_with_nothing_to_draw_is_no_figure():
    _, froc, pr, summary = _tables(["ca"], ap50={"ca": 0.0})
    assert panel_figure("pr", pr, curves_of(summary)) is None  # its only curve has AP 0
    assert panel_figure("froc", froc.iloc[:0], curves_of(summary)) is None
    assert panel_figure("froc", froc, curves_of(summary)) is not None
    plt.close("all")


def test_not_shown_groups_reasons():
    assert not_shown({}) == ""
    assert not_shown({"a": "x", "b": "y", "c": "x"}) == "not shown: a, c (x); b (y)"


def test_chips_are_shown_in_db_over_a_robust_range():
    """A display-scaled chip with black pixels: the old full-range dB mapping crushed
    the clutter into a few grey levels near white; the robust range spreads it."""
    from torchsar_eval.experiments.compare_region.panel import db_display

    g = torch.Generator().manual_seed(0)
    chip = (torch.empty(96, 96).exponential_(generator=g) * 0.15).clamp(max=1)
    chip[torch.rand(96, 96, generator=g) < 0.05] = 0  # black pixels of a display rendering
    d = db_display(chip)
    clutter = d[chip.numpy() > 0]
    assert 0.3 < np.median(clutter) < 0.9
    lo, hi = np.percentile(clutter, [5, 95])
    assert hi - lo > 0.4
    assert d[chip.numpy() == 0].max() == 0


def test_gotcha_figure_is_a_grid(tmp_path):
    from torchsar_eval.experiments.autofocus import gotcha_figure

    g = torch.Generator().manual_seed(0)
    panel = {"reference": torch.rand(21, 21, generator=g)}
    for e in ("1d-uniform-pi", "1d-quadratic-4pi"):
        for m in ("none", "pga-fft", "min-entropy-bp", "sparse-bp"):
            panel[f"{e} / {m}"] = torch.rand(21, 21, generator=g)
    gotcha_figure(panel, tmp_path / "gotcha.png")
    h, w = plt.imread(tmp_path / "gotcha.png").shape[:2]
    assert w / h < 3  # two rows of five, not nine panels in a row


def _peak(img: torch.Tensor) -> tuple[int, int]:
    return divmod(int(img.abs().flatten().argmax()), img.shape[-1])


def test_autofocus_panel_puts_a_point_target_where_the_truth_is():
    """A linear phase error only shifts the image circularly; the panel shows every image
    aligned to the true scene, so a point target's peak lands on the truth."""
    import torchsar.imaging as ti
    import torchsar.sar as sar
    from torchsar_eval.experiments.autofocus import panel_images
    from torchsar_eval.experiments.autofocus.experiment import Formed

    n, where = 32, (10, 20)
    f = torch.zeros(1, 1, n, n, dtype=torch.complex64)
    f[0, 0, where[0], where[1]] = 1.0
    clean = sar.phase_history(f, sar.SpotlightGeometry.for_image((n, n)))
    phi = ti.uniform_phase_error(1, n, amplitude=math.pi, seed=3)
    m = torch.arange(n, dtype=phi.dtype)
    phi = phi + 2 * math.pi * 5 * m / n  # plus a linear phase: a 5-row shift
    g = ti.apply_phase_error(clean, phi)
    sparse = ti.sparse_autofocus(g, error="1d")
    shifted = f.roll(7, dims=-1)  # a method whose image is the scene shifted by 7 columns
    formed = {
        "sparse-autofocus": Formed(sparse.image, sparse.phase, None, 0.0),
        "conventional": Formed(shifted, None, None, 0.0),
    }
    data = {"f": f.abs(), "clean": clean, "g": g, "phi": phi, "mask": f.abs() > 0}
    images = dict(panel_images("1d-uniform-pi", data, formed))
    assert _peak(images["true scene"]) == where
    assert _peak(images["proposed (sparse autofocus)"]) == where
    assert _peak(images["conventional, with error"]) == where
    assert _peak(images["conventional, no error"]) == where
