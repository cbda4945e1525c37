"""The report page: one self-contained HTML file (inline CSS, inline SVG figures, PNG images
as ``data:`` URIs, no script) built from one or more run folders' files."""

from __future__ import annotations

import base64
import html
import json
import math
from dataclasses import replace
from pathlib import Path

import pandas as pd

from torchsar_eval.colours import detector_colour, detector_dash
from torchsar_eval.errors import EvalError
from torchsar_eval.glossary import MATCHING_RULES, TERMS
from torchsar_eval.html_report.figures import FIGURES, figure_svg
from torchsar_eval.html_report.records import Calibration, Matching
from torchsar_eval.html_report.runfiles import RunFiles, read_png
from torchsar_eval.labels import short_labels
from torchsar_eval.leaderboard import (
    DEFAULT_RANK,
    LOWER_IS_BETTER,
    NO_DETECTION,
    RANK_METRICS,
    Board,
    caveats,
    check_rank_by,
    short_value,
)
from torchsar_eval.leaderboard import number as _num
from torchsar_eval.panels import Curve, ap_note
from torchsar_eval.plots import detector_style
from torchsar_eval.tables import PAIRED_COLUMNS

__all__ = ["DEFAULT_RANK", "LOWER_IS_BETTER", "RANK_METRICS", "build_page", "check_rank_by"]

_UNIT = {
    "f1",
    "precision",
    "recall",
    "ap50",
    "ap50_95",
    "ap_distance",
    "pd_at_0.1_fa_per_image",
    "pd_at_1_fa_per_image",
    "pd_at_10_fa_per_image",
    "pauc",
    "fom",
    "mean_iou",
    "pd_object",
    "pd_pixel",
}
LABELS = {
    "f1": "F1",
    "precision": "precision",
    "recall": "recall",
    "ap50": "AP50",
    "ap50_95": "AP50:95",
    "ap_distance": "AP (distance)",
    "pd_at_0.1_fa_per_image": "Pd @ 0.1 FA/img",
    "pd_at_1_fa_per_image": "Pd @ 1 FA/img",
    "pd_at_10_fa_per_image": "Pd @ 10 FA/img",
    "pauc": "pAUC",
    "fom": "FoM",
    "mean_iou": "mean IoU",
    "pd_object": "Pd (object)",
    "pd_pixel": "Pd pixel",
    "pfa_pixel": "Pfa pixel",
    "false_alarms_per_image": "FA/img",
    "fa_per_km2": "FA/km²",
    "false_alarms": "false alarms",
    "tp": "TP",
    "fp": "FP",
    "fn": "FN",
    "fragmentation": "fragments",
    "length_score": "length score",
    "ms_per_image": "ms/img",
    "images_per_s": "images/s",
}
SHOWN = [
    "precision",
    "recall",
    "f1",
    "ap50",
    "ap_distance",
    "pd_at_1_fa_per_image",
    "false_alarms_per_image",
    "tp",
    "fp",
    "fn",
    "pd_pixel",
    "pfa_pixel",
    "ms_per_image",
]
"""Leaderboard columns after the ranking metric (those a run has a value in)."""
_SAMPLE_TYPES = {
    "intensity": "intensity (power), used as is",
    "amplitude": "amplitude, squared to intensity",
    "db": "dB, converted to intensity (10^(x/10))",
    "complex": "complex, |z|² intensity",
    "display": "display rendering (8/16-bit, unknown transfer), scaled to [0, 1] and squared",
}

CSS = """
:root{--fg:#1b1f24;--muted:#5a6472;--line:#d8dee6;--band:#f4f6f9;--best:#e3f4e6;--bar:#9fb3c8;}
*{box-sizing:border-box}
body{margin:0;font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;
color:var(--fg);background:#fff}
header,main,footer{max-width:1240px;margin:0 auto;padding:0 20px}
header{padding-top:18px;border-bottom:1px solid var(--line)}
h1{font-size:22px;margin:0 0 4px}h2{font-size:19px;margin:28px 0 8px;padding-top:8px;
border-top:3px solid var(--fg)}h3{font-size:15px;margin:20px 0 6px}
h4{font-size:14px;margin:14px 0 4px}
.sub,.note,figcaption,.muted{color:var(--muted)}.sub{margin:0 0 8px}
nav ul{list-style:none;padding:0;margin:6px 0 12px;display:flex;flex-wrap:wrap;gap:6px 16px}
a{color:#0b5cad}
.card{background:var(--band);border:1px solid var(--line);border-radius:6px;padding:10px 14px;
display:grid;grid-template-columns:repeat(auto-fill,minmax(260px,1fr));gap:4px 24px}
.card dt{font-weight:600;font-size:12px;color:var(--muted);text-transform:uppercase;
letter-spacing:.03em}.card dd{margin:0 0 6px}
.caveats{margin:8px 0 0;padding-left:20px}.caveats li{color:#8a3b00}
.wrap{overflow-x:auto}
table{border-collapse:collapse;font-size:13px;margin:4px 0}
th,td{padding:3px 8px;border-bottom:1px solid var(--line);text-align:right;white-space:nowrap}
th{background:var(--band);font-weight:600;position:sticky;top:0}
td.l,th.l{text-align:left}.why{white-space:normal;color:var(--muted);font-size:11px;
font-weight:400;max-width:230px;line-height:1.25}
td.best{background:var(--best);font-weight:700}
td.rule{font-size:12px}table.leaderboard th{white-space:normal;vertical-align:bottom}
td.runcell{white-space:normal;max-width:120px}
.sw{display:inline-block;width:22px;height:0;border-top:3px solid;vertical-align:middle;
margin-right:6px;position:relative}
.sw .mk{position:absolute;left:6px;top:-9px;font-size:11px;line-height:1}
.ci{display:inline-flex;align-items:center;gap:6px}
.bar{position:relative;display:inline-block;width:120px;height:10px;background:var(--band);
border:1px solid var(--line);border-radius:2px}
.bar .iv{position:absolute;top:1px;bottom:1px;background:var(--bar);border-radius:2px}
.bar .pt{position:absolute;top:-2px;bottom:-2px;width:2px;margin-left:-1px;background:var(--fg)}
.bar .zero{position:absolute;top:-3px;bottom:-3px;width:1px;background:var(--muted)}
.lohi{font-size:11px;color:var(--muted)}
.figs{display:grid;grid-template-columns:repeat(auto-fill,minmax(340px,1fr));gap:12px}
svg.fig{width:100%;height:auto;display:block}
figure{margin:0}
.legend{display:flex;flex-wrap:wrap;gap:4px 14px;font-size:12px;margin:4px 0 8px}
.cases{display:flex;flex-wrap:wrap;gap:8px}
.case{width:168px;font-size:11px;line-height:1.3;overflow-wrap:anywhere;min-width:0}
.case img{width:160px;height:160px;image-rendering:pixelated;border:1px solid var(--line);
display:block}.case figcaption{max-width:160px}
.kind{font-weight:600;font-size:12px;margin:6px 0 2px}
.overlay{width:316px;font-size:11px;line-height:1.3;overflow-wrap:anywhere;min-width:0}
.overlay img{width:308px;height:auto;border:1px solid var(--line);display:block}
img.other{max-width:100%;height:auto;border:1px solid var(--line)}
.heat{font-variant-numeric:tabular-nums}
footer{margin-top:36px;padding:12px 20px 28px;border-top:1px solid var(--line);font-size:12px}
@media print{
 body{font-size:11px}header,main,footer{max-width:none;padding:0}nav{display:none}
 section.dataset{break-before:page}h2{break-after:avoid}h3,h4{break-after:avoid}
 figure,.case,tr,.card{break-inside:avoid}.wrap{overflow:visible}th{position:static}
 table.leaderboard{font-size:9px}table.leaderboard th,table.leaderboard td{padding:2px 4px}
 .bar{width:60px}
 *{-webkit-print-color-adjust:exact;print-color-adjust:exact}
 .figs{grid-template-columns:repeat(2,1fr)}
}
"""


def _e(v: object) -> str:
    return html.escape(str(v), quote=True)


def _fmt(metric: str, v: object) -> str:
    x = _num(v)
    if math.isnan(x):
        return "–"
    if metric in ("tp", "fp", "fn", "false_alarms", "images", "targets"):
        return f"{x:.0f}"
    if x == 0:
        return "0"
    if metric in ("pfa_pixel",) or abs(x) < 1e-3:
        return f"{x:.2e}"
    if metric in _UNIT:
        return f"{x:.3f}"
    return f"{x:.3g}" if abs(x) < 1000 else f"{x:,.0f}"


def _png_uri(folder: Path, name: str) -> str | None:
    """PNG ``name`` of run folder ``folder`` as a data URI (``None``: not a figure of the
    run, see :func:`~torchsar_eval.html_report.runfiles.read_png`)."""
    data = read_png(folder, name)
    if data is None:
        return None
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() else "-" for c in text).strip("-").lower() or "x"


def _series(board: Board) -> list[Curve]:
    """One curve per row of ``board``, coloured by detector name (dashed by run when the
    board compares runs)."""
    out = []
    for _, r in board.rows.sort_values(["_run"], kind="stable").iterrows():
        dash = (
            detector_dash(r["detector"])
            if len(board.runs) == 1
            else (["-", "--", ":", "-."][int(r["_run"]) % 4])
        )
        colour, marker = detector_colour(r["detector"]), detector_style(r["detector"])["marker"]
        out.append(Curve(r["label"], r["detector"], colour, dash, r, marker))
    return out


_GLYPHS = {
    "o": "\u25cf",
    "s": "\u25a0",
    "^": "\u25b2",
    "v": "\u25bc",
    "D": "\u25c6",
    "P": "\u271a",
    "X": "\u2716",
    "<": "\u25c0",
    ">": "\u25b6",
    "h": "\u2b22",
    "p": "\u2b1f",
    "*": "\u2605",
    "d": "\u2666",
    "H": "\u2b23",
    "8": "\u2bc3",
}
"""The figures' markers as characters, for the legends in the page's text."""


def _swatch(detector: str, dash: str = "-", marker: bool = False) -> str:
    """A detector's line (colour, dash) as an inline swatch; with its figure marker on it
    when ``marker``."""
    style = {"-": "solid", "--": "dashed", ":": "dotted", "-.": "dashed"}[dash]
    colour = detector_colour(detector)
    glyph = _GLYPHS.get(detector_style(detector)["marker"], "") if marker else ""
    mark = f'<span class="mk" style="color:{colour}">{glyph}</span>' if glyph else ""
    return (
        f'<span class="sw" style="border-top-color:{colour};border-top-style:{style}">{mark}</span>'
    )


def _bar(value: float, lo: float, hi: float, top: float, zero: float | None = None) -> str:
    """An interval bar on ``[0, top]`` (or ``[-top, top]`` when ``zero`` is given)."""
    base = -top if zero is not None else 0.0
    span = (top - base) or 1.0

    def pos(x: float) -> float:
        return 100 * min(max((x - base) / span, 0.0), 1.0)

    parts = ['<span class="bar">']
    if zero is not None:
        parts.append(f'<span class="zero" style="left:{pos(0):.1f}%"></span>')
    if not (math.isnan(lo) or math.isnan(hi)):
        parts.append(
            f'<span class="iv" style="left:{pos(lo):.1f}%;'
            f'width:{max(pos(hi) - pos(lo), 0.8):.1f}%"></span>'
        )
    if not math.isnan(value):
        parts.append(f'<span class="pt" style="left:{pos(value):.1f}%"></span>')
    return "".join(parts) + "</span>"


def _best(values: list[float], metric: str) -> float | None:
    finite = [v for v in values if not math.isnan(v)]
    if len(set(finite)) < 2:
        return None
    return min(finite) if metric in LOWER_IS_BETTER else max(finite)


def _leaderboard(board: Board) -> str:
    rows, m = board.rows, board.rank_by
    if rows.empty:
        return '<p class="muted">No rows.</p>'
    shown = [
        c
        for c in SHOWN
        if c in rows.columns and c != m and pd.to_numeric(rows[c], errors="coerce").notna().any()
    ]
    many = len(board.runs) > 1
    val = {c: [_num(v) for v in rows[c]] for c in [m, *shown] if c in rows.columns}
    silent = [n == NO_DETECTION for n in board.notes]  # fewest false alarms, trivially
    best = {
        c: _best(
            [math.nan if q and c in LOWER_IS_BETTER else x for x, q in zip(v, silent, strict=True)],
            c,
        )
        for c, v in val.items()
    }
    has_ci = f"{m}_lo" in rows.columns and f"{m}_hi" in rows.columns
    lo = [_num(v) for v in rows[f"{m}_lo"]] if has_ci else [math.nan] * len(rows)
    hi = [_num(v) for v in rows[f"{m}_hi"]] if has_ci else [math.nan] * len(rows)
    top = (
        1.0
        if m in _UNIT
        else max([x for x in [*val.get(m, []), *hi] if not math.isnan(x)] or [1.0]) or 1.0
    )
    head = ['<th class="l">#</th>', '<th class="l">detector</th>']
    head += ['<th class="l">run</th>'] if many else []
    arrow = "↓ lower is better" if m in LOWER_IS_BETTER else "↑ higher is better"
    head.append(
        f'<th class="l" title="{_e(arrow)}">{_e(LABELS.get(m, m))} '
        f'<span class="lohi">95 % interval</span></th>'
    )
    head += [f'<th title="{_e(c)}">{_e(LABELS.get(c, c))}</th>' for c in shown]
    head.append(
        '<th class="l" title="the IoU of each row\'s AP (a cell\'s title: its matching rule)">'
        "IoU</th>"
    )
    body = []
    for i, r in rows.iterrows():
        rank = board.rank[i]
        v = val[m][i] if m in val else math.nan
        cls = ' class="l best"' if best.get(m) is not None and v == best[m] else ' class="l"'
        interval = (
            f'<span class="lohi">{_fmt(m, lo[i])}–{_fmt(m, hi[i])}</span>'
            if has_ci and not math.isnan(lo[i])
            else ""
        )
        why = f'<div class="why">{_e(board.notes[i])}</div>' if board.notes[i] else ""
        cells = [
            f'<td class="l">{"" if rank is None else rank}</td>',
            f'<td class="l det">{_swatch(r["detector"])}{_e(r["detector"])}{why}</td>',
        ]
        if many:
            differs = board.settings[i]
            note = f'<div class="why">{_e(differs)}</div>' if differs else ""
            cells.append(f'<td class="l runcell">{_e(r["run"])}{note}</td>')
        cells.append(
            f'<td{cls}><span class="ci"><b>{_fmt(m, v)}</b>'
            f"{_bar(v, lo[i], hi[i], top)}{interval}</span></td>"
        )
        for c in shown:
            x = val[c][i]
            mark = ' class="best"' if best[c] is not None and x == best[c] else ""
            cells.append(f"<td{mark}>{_fmt(c, x)}</td>")
        cells.append(f'<td class="l rule" title="{_e(_measured_by(r))}">{_e(_iou(r))}</td>')
        body.append("<tr>" + "".join(cells) + "</tr>")
    return (
        '<div class="wrap"><table class="leaderboard"><thead><tr>'
        + "".join(head)
        + "</tr></thead><tbody>"
        + "".join(body)
        + "</tbody></table></div>"
    )


def _iou(row: pd.Series) -> str:
    """A leaderboard row's IoU type in a word (``summary.csv``'s ``iou_type``)."""
    kind = row.get("iou_type")
    if not isinstance(kind, str) or not kind:
        return "–"
    if kind == "point":
        return "point: no AP"  # points have no IoU: matched by the rule, no AP
    return kind if kind in ("distance", "centroid") else f"{kind} IoU"


def _measured_by(row: pd.Series) -> str:
    """A leaderboard row's matching rule and IoU type (``summary.csv``'s ``matching``;
    ``–`` for a run written before rows said so)."""
    text = row.get("matching")
    return text if isinstance(text, str) and text else "–"


def _rule_text(match: Matching) -> str:
    """The matching rule in words (its kind and distance when the rule is not a known one)."""
    rule = MATCHING_RULES.get(match.kind)
    try:
        text = rule.format(**match.fields) if rule else None
    except (KeyError, ValueError):
        text = None
    if text is None:
        text = f"{match.kind}" + (
            f", within {match.max_distance:g} {match.distance_units}" if match.max_distance else ""
        )
    return text


def _operating_point(cal: Calibration | None) -> str:
    """How the reported operating point was chosen."""
    if cal is None:
        return "each detector's design threshold"
    if cal.sweep:
        swept = ", ".join(f"{k} in {{{', '.join(map(str, v))}}}" for k, v in cal.sweep.items())
        return (
            f"settings chosen on {cal.fraction} of the images for {cal.target} ({swept}), "
            "each at its design threshold; reported on the rest (see Tuned settings)"
        )
    return f"calibrated on {cal.fraction} of the images for {cal.target}, reported on the rest"


def _card(run: RunFiles, dataset: str, board: Board, label: str | None) -> str:
    rec, ds = run.record, run.record.dataset(dataset)
    summary = run.table("summary", dataset)
    first = summary.iloc[0] if not summary.empty else pd.Series(dtype=object)
    facts: list[tuple[str, str]] = []
    if label:
        facts.append(("run", label))
    if ds.source:
        facts.append(
            (
                "source",
                f"{ds.scheme + ': ' if ds.scheme else ''}{ds.source}"
                + (f" ({ds.files} files)" if ds.files is not None else ""),
            )
        )
    facts.append(("images", _fmt("images", first.get("images"))))
    facts.append(("targets", _fmt("targets", first.get("targets"))))
    bd = run.table("breakdown", dataset)
    if {"by", "key", "targets", "detector"} <= set(bd.columns) and not bd.empty:
        one = bd[(bd["detector"] == bd["detector"].iloc[0]) & (bd["by"] == "class")]
        if not one.empty:
            pairs = zip(one["key"], one["targets"], strict=True)
            facts.append(("classes", ", ".join(f"{k} ({_fmt('targets', t)})" for k, t in pairs)))
    if ds.image_sizes:
        facts.append(("image size", ", ".join(f"{h} × {w} px" for h, w in ds.image_sizes)))
    if ds.sample_type:
        facts.append(("samples", _SAMPLE_TYPES.get(ds.sample_type, ds.sample_type)))
    spacing = ds.spacings or ([ds.pixel_spacing] if ds.pixel_spacing else [])
    facts.append(
        (
            "pixel spacing",
            ", ".join(
                f"{_num(s[0]):g} × {_num(s[1]):g} m"
                if isinstance(s, list | tuple)
                else f"{_num(s):g} m"
                for s in spacing
            )
            if spacing
            else "unknown (no false alarms per km², no sizes in m)",
        )
    )
    if ds.gt or ds.instances:
        facts.append(("ground truth", " · ".join(v for v in (ds.gt, ds.instances) if v)))
    if rec.matching is not None:
        facts.append(("matching rule", _rule_text(rec.matching)))
    if rec.objects is not None:
        rules = rec.objects
        area = float("nan") if rules.min_area is None else rules.min_area
        facts.append(
            (
                "objects",
                f"closing {rules.closing} px, components over "
                f"{_floor_text(rules.floor)}, area ≥ {area:g} {rules.units}",
            )
        )
    if rec.bootstrap is not None:
        facts.append(
            (
                "intervals",
                f"95 %, effective-count Jeffreys / Poisson from a Poisson "
                f"bootstrap over images, {rec.bootstrap.replicates} replicates"
                if rec.bootstrap.replicates
                else "none (bootstrap off)",
            )
        )
    facts.append(("operating point", _operating_point(rec.calibration)))
    if rec.despeckle:
        facts.append(("despeckling", ", ".join(f"{k}={v}" for k, v in rec.despeckle.items())))
    if ds.wall_s is not None:
        speed = float("nan") if ds.images_per_s is None else ds.images_per_s
        facts.append(("time", f"{ds.wall_s:.1f} s ({speed:.3g} images/s)"))
    notes = caveats(run, dataset, board)
    out = ['<dl class="card">']
    out += [f"<div><dt>{_e(k)}</dt><dd>{_e(v)}</dd></div>" for k, v in facts]
    out.append("</dl>")
    if notes:
        out.append('<ul class="caveats">' + "".join(f"<li>{_e(c)}</li>" for c in notes) + "</ul>")
    return "".join(out)


def _with_ap(c: Curve) -> str:
    """A curve's label with its AP in brackets (when its summary has one)."""
    note = ap_note(c)
    return c.label + (f" ({note})" if note else "")


def _legend(series: list[Curve]) -> str:
    """The figures' shared legend: each line's style, marker and label, with its AP."""
    items = [
        f"<span>{_swatch(s.detector, s.dash, marker=True)}{_e(_with_ap(s))}</span>" for s in series
    ]
    return '<div class="legend">' + "".join(items) + "</div>"


def _tuned(board: Board) -> str:
    """The settings a sweep chose for each detector on the calibration split, with its
    numbers there and how many settings it tried (``sweep.csv``)."""
    out = []
    for run in board.runs:
        sweep = run.table("sweep", board.dataset)
        if sweep.empty or "chosen" not in sweep.columns:
            continue
        chosen = sweep[sweep["chosen"].astype(str).str.lower().isin(["true", "1"])]
        tried = sweep.groupby("detector").size()
        order = [d for d in _order(board, run) if d in set(chosen["detector"])]
        rows = chosen.set_index("detector").loc[order].reset_index()
        df = pd.DataFrame(
            {
                "detector": rows["detector"],
                "chosen settings": [
                    ", ".join(f"{k}={short_value(v)}" for k, v in json.loads(o).items())
                    for o in rows["options"]
                ],
                "F1 (calibration)": rows["f1"].astype(float),
                "FA/img (calibration)": rows["false_alarms_per_image"].astype(float),
                "settings tried": [int(tried[d]) for d in rows["detector"]],
            }
        )
        title = f"<h4>{_e(run.name)}</h4>" if len(board.runs) > 1 else ""
        out.append(title + _table(df))
    if not out:
        return ""
    return (
        '<h3>Tuned settings</h3><p class="note">Each detector\'s setting chosen on the '
        "calibration split (every setting tried is in sweep.csv); the leaderboard reports "
        "it on the disjoint test split.</p>" + "".join(out)
    )


def _figures(board: Board, salt: str) -> str:
    series = _series(board)
    figs = []
    for kind, panel in FIGURES.items():
        frames = [run.table(panel.table, board.dataset) for run in board.runs]
        if len(board.runs) > 1:
            frames = [_relabel(f, run.name) for f, run in zip(frames, board.runs, strict=True)]
            ser = [replace(s, detector=s.label) for s in series]
        else:
            ser = series
        frames = [f for f in frames if not f.empty]
        if not frames:
            continue
        svg = figure_svg(kind, pd.concat(frames, ignore_index=True), ser, salt)
        if svg:
            figs.append(f"<figure>{svg}</figure>")
    if not figs:
        return '<p class="muted">No curves in this run.</p>'
    note = (
        '<p class="note">Large markers with a black edge: each detector\'s operating point. '
        "Colours, line styles and markers are "
        "fixed per detector name.</p>"
    )
    return _legend(series) + '<div class="figs">' + "".join(figs) + "</div>" + note


def _relabel(df: pd.DataFrame, run: str) -> pd.DataFrame:
    if "detector" not in df.columns:
        return df
    df = df.copy()
    df["detector"] = [f"{d} ({run})" for d in df["detector"]]
    return df


def _table(df: pd.DataFrame, left: int = 1) -> str:
    head = "".join(
        f"<th{' class=l' if i < left else ''}>{_e(c)}</th>" for i, c in enumerate(df.columns)
    )
    body = []
    for row in df.itertuples(index=False):
        cells = []
        for i, v in enumerate(row):
            text = _fmt(str(df.columns[i]), v) if isinstance(v, float) else str(v)
            cells.append(f"<td{' class=l' if i < left else ''}>{_e(text)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return (
        '<div class="wrap"><table><thead><tr>'
        + head
        + "</tr></thead><tbody>"
        + "".join(body)
        + "</tbody></table></div>"
    )


def _order(board: Board, run: RunFiles) -> list[str]:
    """The run's detectors in leaderboard order."""
    r = board.rows[board.rows["run"] == run.name]
    return list(dict.fromkeys(r["detector"]))


_AP_SIZES = [
    ("ap50", "AP50"),
    ("ap50_95", "AP50:95"),
    ("ap_small", "small"),
    ("ap_medium", "medium"),
    ("ap_large", "large"),
]


def ap_frame(summary: pd.DataFrame, breakdown: pd.DataFrame, order: list[str]) -> pd.DataFrame:
    """A dataset's AP per detector (``order``): AP50 and AP50:95, AP50:95 by COCO size, and
    AP50:95 per ground-truth class (``breakdown.csv``'s class rows, when matching is per
    class); empty when no detector has an AP at an IoU.

    Examples:
        >>> s = pd.DataFrame({"detector": ["a"], "ap50": [0.9], "ap50_95": [0.5],
        ...                   "ap_small": [0.2], "ap_medium": [0.6], "ap_large": [float("nan")]})
        >>> b = pd.DataFrame({"detector": ["a", "a"], "by": ["class", "class"],
        ...                   "key": ["ship", "boat"], "ap50_95": [0.55, 0.45]})
        >>> ap_frame(s, b, ["a"]).columns.tolist()
        ['detector', 'AP50', 'AP50:95', 'small', 'medium', 'large', 'boat', 'ship']
    """
    have = [(c, h) for c, h in _AP_SIZES if c in summary.columns]
    if not have or not any(summary[c].notna().any() for c, _ in have):
        return pd.DataFrame()
    rows = summary.drop_duplicates("detector").set_index("detector")
    out = pd.DataFrame({"detector": [d for d in order if d in rows.index]})
    for c, h in have:
        out[h] = [float(rows.loc[d, c]) for d in out["detector"]]
    if {"by", "key", "ap50_95"} <= set(breakdown.columns):
        cls = breakdown[(breakdown["by"] == "class") & breakdown["ap50_95"].notna()]
        for name in sorted(set(cls["key"].astype(str))):
            per = cls[cls["key"].astype(str) == name].drop_duplicates("detector")
            values = dict(zip(per["detector"], per["ap50_95"], strict=True))
            out[name] = [float(values.get(d, float("nan"))) for d in out["detector"]]
    return out


def _ap(board: Board) -> str:
    """AP by size and per class, one table per run."""
    out = []
    for run in board.runs:
        df = ap_frame(
            run.table("summary", board.dataset),
            run.table("breakdown", board.dataset),
            _order(board, run),
        )
        if df.empty:
            continue
        title = f"<h4>{_e(run.name)}</h4>" if len(board.runs) > 1 else ""
        out.append(title + _table(df))
    if not out:
        return ""
    return (
        '<h3>AP by size and class</h3><p class="note">COCO average precision (101-point, '
        "every detection ranked); small / medium / large: AP50:95 of the targets in "
        "COCO's area ranges (&lt; 32², to 96², above); a class: AP50:95 of its targets "
        "(per-class matching).</p>" + "".join(out)
    )


def _breakdown(board: Board) -> str:
    out = []
    for run in board.runs:
        bd = run.table("breakdown", board.dataset)
        if bd.empty or not {"detector", "by", "key", "tp", "targets"} <= set(bd.columns):
            continue
        keys = list(dict.fromkeys(zip(bd["by"], bd["key"], strict=True)))
        head = ['<th class="l">detector</th>']
        for by, key in keys:
            n = bd[(bd["by"] == by) & (bd["key"] == key)]["targets"].iloc[0]
            head.append(
                f'<th>{_e(by)}: {_e(key)}<br><span class="lohi">'
                f"{_fmt('targets', n)} targets</span></th>"
            )
        body = []
        for det in _order(board, run):
            d = bd[bd["detector"] == det]
            cells = [f'<td class="l">{_swatch(det)}{_e(det)}</td>']
            for by, key in keys:
                row = d[(d["by"] == by) & (d["key"] == key)]
                if row.empty:
                    cells.append("<td>–</td>")
                    continue
                tp, n = _num(row["tp"].iloc[0]), _num(row["targets"].iloc[0])
                fp = _num(row["fp"].iloc[0]) if "fp" in row else math.nan
                rec = tp / n if n else math.nan
                shade = (
                    ""
                    if math.isnan(rec)
                    else (f' style="background:rgba(46,160,67,{0.08 + 0.32 * rec:.2f})"')
                )
                extra = "" if math.isnan(fp) else f" · {fp:.0f} FA"
                cells.append(
                    f'<td class="heat"{shade}>{tp:.0f}/{n:.0f}<span class="lohi">'
                    f"{extra}</span></td>"
                )
            body.append("<tr>" + "".join(cells) + "</tr>")
        title = f"<h4>{_e(run.name)}</h4>" if len(board.runs) > 1 else ""
        out.append(
            title
            + '<div class="wrap"><table><thead><tr>'
            + "".join(head)
            + "</tr></thead><tbody>"
            + "".join(body)
            + "</tbody></table></div>"
        )
    if not out:
        return ""
    return (
        '<h3>Breakdown</h3><p class="note">Targets found / targets at the operating point '
        "(shaded by recall), false alarms where they can be attributed.</p>" + "".join(out)
    )


_ERROR_FAMILIES = [
    (
        "false_alarm",
        "False alarms by type",
        "each false alarm counted once, under the first type that applies",
    ),
    (
        "miss",
        "Missed targets by size and SCR",
        "each missed target counted once per family: size bins, then SCR bins",
    ),
]


def _errors(board: Board) -> str:
    """``errors.csv`` as two tables: the false alarms by type, the misses by size and SCR
    bin (detectors in leaderboard order)."""
    out = []
    for run in board.runs:
        df = run.table("errors", board.dataset)
        if df.empty:
            continue
        head = f"<h4>{_e(run.name)}</h4>" if len(board.runs) > 1 else ""
        if not {"detector", "error", "type", "count"} <= set(df.columns):
            out.append(head + _table(df.drop(columns=[c for c in ("dataset",) if c in df.columns])))
            continue
        order = _order(board, run)
        parts = []
        for family, title, note in _ERROR_FAMILIES:
            part = df[df["error"] == family]
            if part.empty:
                continue
            piv = part.pivot_table(
                index="detector", columns="type", values="count", aggfunc="sum", sort=False
            )
            piv = piv.reindex(
                [d for d in order if d in piv.index] + [d for d in piv.index if d not in order]
            )
            parts.append(
                f'<h4>{_e(title)}</h4><p class="note">{_e(note)}</p>' + _table(piv.reset_index())
            )
        out.append(head + "".join(parts))
    return "<h3>Errors</h3>" + "".join(out) if out else ""


def _paired(board: Board) -> str:
    out = []
    for run in board.runs:
        df = run.table("paired", board.dataset)
        if df.empty:
            continue
        cols = set(df.columns)  # paired.csv's own columns (PAIRED_COLUMNS), where present
        diff, lo, hi, sig = (c if c in cols else None for c in PAIRED_COLUMNS[4:8])
        names = [c for c in ("detector", "reference", "metric") if c in df.columns]
        if diff is None:
            out.append(_table(df.drop(columns=[c for c in ("dataset",) if c in df.columns])))
            continue
        vals = [abs(_num(v)) for c in (diff, lo, hi) if c for v in df[c]]
        top = max([v for v in vals if not math.isnan(v)] or [1.0]) or 1.0
        head = "".join(f'<th class="l">{_e(c)}</th>' for c in names)
        head += '<th class="l">difference <span class="lohi">95 % interval</span></th>'
        head += '<th class="l">significant</th>' if sig else ""
        body = []
        for _, r in df.iterrows():
            d = _num(r[diff])
            a, b = (_num(r[lo]) if lo else math.nan), (_num(r[hi]) if hi else math.nan)
            cells = "".join(f'<td class="l">{_e(r[c])}</td>' for c in names)
            interval = "" if math.isnan(a) else f'<span class="lohi">{a:+.3g} … {b:+.3g}</span>'
            if math.isnan(d):  # not defined for this pair (e.g. AP of points): no bar
                cells += '<td class="l">–</td>'
            else:
                cells += (
                    f'<td class="l"><span class="ci"><b>{d:+.3g}</b>'
                    f"{_bar(d, a, b, top, zero=0.0)}{interval}</span></td>"
                )
            if sig:
                yes = str(r[sig]).strip().lower() in ("true", "1", "yes", "1.0")
                cells += f'<td class="l">{"<b>yes</b>" if yes else "no"}</td>'
            body.append("<tr>" + cells + "</tr>")
        out.append(
            (f"<h4>{_e(run.name)}</h4>" if len(board.runs) > 1 else "")
            + '<div class="wrap"><table><thead><tr>'
            + head
            + "</tr></thead><tbody>"
            + "".join(body)
            + "</tbody></table></div>"
        )
    if not out:
        return ""
    return (
        '<h3>Paired differences</h3><p class="note">Differences to the reference detector '
        "on the same images (paired bootstrap); the bar is centred on zero.</p>" + "".join(out)
    )


def _coco(board: Board) -> str:
    out = []
    for run in board.runs:
        df = run.table("coco", board.dataset)
        if not df.empty:
            out.append(_table(df.drop(columns=[c for c in ("dataset",) if c in df.columns]), 2))
    return "<h3>COCO-compatible statistics</h3>" + "".join(out) if out else ""


_KINDS = [
    ("false_alarm", "highest-scoring false alarms"),
    ("miss", "largest missed targets"),
    ("hit", "typical hits (true positives drawn at random)"),
]


def _caption(kind: str, rank: int, r: pd.Series) -> str:
    where = f"{_e(r.get('image', ''))} (row {_num(r.get('row')):.0f}, col {_num(r.get('col')):.0f})"
    score = _num(r.get("score"))
    area = _num(r.get("area"))
    cls = r.get("class")
    cls = "" if cls is None or (isinstance(cls, float) and math.isnan(cls)) else f" {_e(cls)}"
    why = r.get("why")
    why = why if isinstance(why, str) and why else ""
    if kind in ("false_alarm", "hit"):
        what = f"score {score:.3g}" + ("" if math.isnan(area) else f" · {area:.0f} px")
    else:
        found = why or "no match"
        if not math.isnan(score):
            found = f"matched below threshold ({score:.3g})"
        what = ("" if math.isnan(area) else f"{area:.0f} px{cls} · ") + _e(found)
    if kind in ("false_alarm", "hit") and why:
        what += f"<br>{_e(why)}"
    return f"<b>#{rank}</b> {where}<br>{what}"


def _gallery(board: Board) -> str:
    out = []
    for run in board.runs:
        cases = run.table("cases", board.dataset)
        need = {"detector", "kind", "file"}
        if cases.empty or not need <= set(cases.columns):
            continue
        for det in _order(board, run):
            d = cases[cases["detector"] == det]
            label = det if len(board.runs) == 1 else f"{det} ({run.name})"
            parts = [f"<h4>{_swatch(det)}{_e(label)}</h4>"]
            for kind, title in _KINDS:
                k = d[d["kind"] == kind]
                figs = []
                for rank, (_, r) in enumerate(k.iterrows(), 1):
                    uri = _png_uri(run.folder, str(r["file"]))
                    if uri is None:
                        continue
                    alt = f"{kind.replace('_', ' ')} {rank} of {det}"
                    figs.append(
                        f'<figure class="case"><img src="{uri}" width="160" '
                        f'height="160" alt="{_e(alt)}"><figcaption>'
                        f"{_caption(kind, rank, r)}</figcaption></figure>"
                    )
                count = f"{len(figs)} shown" if figs else "none"
                parts.append(f'<div class="kind">{_e(title)}: {count}</div>')
                if figs:
                    parts.append('<div class="cases">' + "".join(figs) + "</div>")
            out.append("".join(parts))
    if not out:
        return ""
    return (
        '<h3>Worst cases and typical hits</h3><p class="note">At the design operating point, '
        "chosen over the whole dataset. Green: ground truth; magenta: detections; yellow: "
        "don't-care pixels; the case's own object is outlined twice as thick.</p>" + "".join(out)
    )


def _overlays(board: Board) -> str:
    """Each drawn image in a row of its detectors' overlays (leaderboard order)."""
    out = []
    for run in board.runs:
        df = run.table("overlays", board.dataset)
        if df.empty or not {"detector", "image", "file"} <= set(df.columns):
            continue
        order = {d: k for k, d in enumerate(_order(board, run))}
        for image, rows in df.groupby("image", sort=False):
            rows = rows.sort_values("detector", key=lambda c: c.map(order).fillna(len(order)))
            figs = []
            for _, r in rows.iterrows():
                small = r.get("small")
                small = str(small) if isinstance(small, str) and small else str(r["file"])
                uri = _png_uri(run.folder, small)
                if uri is None:
                    continue
                det = str(r["detector"])
                label = det if len(board.runs) == 1 else f"{det} ({run.name})"
                n, found = int(_num(r.get("targets"))), int(_num(r.get("found")))
                fa = int(_num(r.get("false_alarms")))
                thr = _num(r.get("threshold"))
                at = "" if math.isnan(thr) else f" · threshold {thr:.4g}"
                img = f'<img src="{uri}" alt="{_e(det)} on {_e(image)}">'
                if len(board.runs) == 1:  # the full-size picture, next to the report
                    img = f'<a href="{_e(str(r["file"]))}">{img}</a>'
                figs.append(
                    f'<figure class="overlay">{img}'
                    f"<figcaption>{_swatch(det)}<b>{_e(label)}</b>: {found} of {n} targets "
                    f"found, {fa} false alarm{'s' * (fa != 1)}{at}</figcaption></figure>"
                )
            if figs:
                out.append(
                    f'<div class="kind">{_e(str(image))}</div>'
                    f'<div class="cases">{"".join(figs)}</div>'
                )
    if not out:
        return ""
    return (
        '<h3>Whole images</h3><p class="note">Each detector at its reported operating '
        "point. Green: targets found; orange (thick): targets missed; cyan: detections "
        "matching a target; magenta: false alarms; yellow: don't-care regions.</p>" + "".join(out)
    )


def _floor_text(floor: float) -> str:
    """Where the discrimination stage cuts: the design threshold, or a fraction of it."""
    return "the design threshold" if floor == 1 else f"{floor:g} x the design threshold"


def _header(runs: list[RunFiles], rank_by: str) -> tuple[str, str]:
    if len(runs) == 1:
        run, rec = runs[0], runs[0].record
        title = f"Evaluation report: {run.name}"
        sub = [f"run {run.name}"]
        if rec.time:
            sub.append(f"created {rec.time}")
        if rec.torchsar_version:
            sub.append(f"torchsar {rec.torchsar_version}, torch {rec.torch_version}")
    else:
        title = "Evaluation report: " + " vs ".join(r.name for r in runs)
        sub = [
            f"{len(runs)} runs: "
            + ", ".join(
                f"{r.name}" + (f" ({r.record.time})" if r.record.time else "") for r in runs
            )
        ]
    sub.append(f"ranked by {LABELS.get(rank_by, rank_by)}")
    return title, f'<h1>{_e(title)}</h1><p class="sub">{_e(" · ".join(sub))}</p>'


def _datasets(runs: list[RunFiles]) -> list[str]:
    return list(dict.fromkeys(d for run in runs for d in run.datasets))


def _others(runs: list[RunFiles]) -> str:
    out = []
    for run in runs:
        for path in run.figures:
            uri = _png_uri(run.folder, path.name)
            if uri:
                name = path.name if len(runs) == 1 else f"{run.name}/{path.name}"
                out.append(
                    f'<figure><img class="other" src="{uri}" alt="{_e(name)}">'
                    f"<figcaption>{_e(name)}</figcaption></figure>"
                )
    return "<section><h2>Other figures</h2>" + "".join(out) + "</section>" if out else ""


def _glossary() -> str:
    rows = "".join(
        f'<tr><td class="l">{_e(k)}</td><td class="l" style="white-space:normal">{_e(v)}</td></tr>'
        for k, v in TERMS
    )
    return (
        '<section><h2>Glossary</h2><div class="wrap"><table><tbody>'
        + rows
        + "</tbody></table></div></section>"
    )


def build_page(runs: list[RunFiles], rank_by: str = DEFAULT_RANK) -> str:
    """The report of ``runs`` (one run, or several compared) as one HTML document."""
    if not runs:
        raise EvalError("no run folder given")
    columns = {c for run in runs for c in run.tables["summary"].columns}
    columns |= {c for run in runs for c in run.tables["timing"].columns}
    check_rank_by(rank_by, columns)
    title, header = _header(runs, rank_by)
    names = _datasets(runs)
    short = short_labels(names)  # the full spec is in the card's source and config.json
    nav = "".join(
        f'<li><a href="#ds-{i}" title="{_e(n)}">{_e(short[n])}</a></li>'
        for i, n in enumerate(names, 1)
    )
    sections = []
    for i, name in enumerate(names, 1):
        board = Board(runs, name, rank_by)
        cards = "".join(
            _card(run, name, board, run.name if len(runs) > 1 else None)
            for run in runs
            if name in run.datasets
        )
        sections.append(
            f'<section class="dataset" id="ds-{i}"><h2 title="{_e(name)}">{_e(short[name])}</h2>'
            f"{cards}"
            f"<h3>Leaderboard</h3>{_leaderboard(board)}{_tuned(board)}"
            f"<h3>Curves</h3>{_figures(board, f'ds{i}-{_slug(name)}')}"
            f"{_ap(board)}{_paired(board)}{_errors(board)}{_breakdown(board)}{_coco(board)}"
            f"{_gallery(board)}{_overlays(board)}</section>"
        )
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{_e(title)}</title><style>{CSS}</style></head><body>"
        f'<header>{header}<nav><ul>{nav}<li><a href="#glossary">glossary</a></li></ul></nav>'
        f"</header><main>{''.join(sections)}{_others(runs)}"
        f'<div id="glossary">{_glossary()}</div></main>'
        "<footer>Written by torchsar-eval from the run folder's files; rebuild it with "
        "<code>torchsar-eval report RUN</code>.</footer></body></html>\n"
    )
