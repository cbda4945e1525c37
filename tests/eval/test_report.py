"""``report.html``: written by every run, self-contained and offline, leaderboards in ranked
order, every figure embedded, rebuilt identically from the run folder by ``torchsar-eval
report``, several runs compared in one page, optional tables shown when present."""

from __future__ import annotations

import base64
import json
import re
import shutil
from html.parser import HTMLParser

import pandas as pd
import pytest

import torchsar_eval as te
from torchsar_eval.cli import main
from torchsar_eval.colours import PALETTE, detector_colour, detector_dash
from torchsar_eval.errors import EvalError
from torchsar_eval.html_report import build_report
from torchsar_eval.html_report.page import NO_DETECTION
from torchsar_eval.registry import BUILTIN
from torchsar_eval.tables import SCR_COLUMNS

pytestmark = pytest.mark.figures  # every run here is reported


class Page(HTMLParser):
    """What the tests read of a page: leaderboards (detector cells in row order), images,
    inline figures, every ``src`` / ``href``, tags used."""

    def __init__(self, text: str) -> None:
        super().__init__()
        self.boards: list[list[list[str]]] = []
        self.images: list[str] = []
        self.figures = 0
        self.links: list[str] = []
        self.tags: set[str] = set()
        self._cell: list[str] | None = None
        self._row: list[str] | None = None
        self._in_board = False
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.add(tag)
        self.links += [v for k, v in attrs if k in ("src", "href", "xlink:href") and v]
        if tag == "table" and "leaderboard" in (a.get("class") or ""):
            self._in_board = True
            self.boards.append([])
        elif tag == "tr" and self._in_board:
            self._row = []
        elif tag == "td" and self._row is not None:
            self._cell = []
        elif tag == "img":
            self.images.append(a.get("src", ""))
        elif tag == "svg" and "fig" in (a.get("class") or ""):
            self.figures += 1

    def handle_endtag(self, tag):
        if tag == "table" and self._in_board:
            self._in_board = False
        elif tag == "tr" and self._row is not None:
            if self._row:
                self.boards[-1].append(self._row)
            self._row = None
        elif tag == "td" and self._cell is not None:
            self._row.append(" ".join(" ".join(self._cell).split()))
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A default-style small run: simulated chips, two detectors, the run folder written."""
    out = tmp_path_factory.mktemp("runs") / "a"
    res = te.evaluate("sim-chips", ["ca", "so"], n=4, out=out, progress=False)
    return out, res


@pytest.fixture(scope="module")
def other(run):
    """A second run of the same images: ca again, and vi."""
    out = run[0].parent / "b"
    te.evaluate("sim-chips", ["ca", "vi"], n=4, out=out, progress=False)
    return out


def _copy(run, tmp_path, name="copy"):
    dst = tmp_path / name
    shutil.copytree(run[0], dst, ignore=shutil.ignore_patterns("shards"))
    return dst


def _detectors(row_cells: list[list[str]]) -> list[str]:
    """Detector names of leaderboard rows (the detector cell, its note left out)."""
    return [cells[1].split(" ")[0] for cells in row_cells]


def test_every_run_folder_has_a_report_and_a_gallery(run):
    out, res = run
    assert "report.html" in res.files and "gallery/" in res.files
    assert (out / "report.html").is_file() and (out / "gallery" / "cases.csv").is_file()
    page = (out / "report.html").read_text()
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    config = json.loads((out / "config.json").read_text())["options"]
    assert config["rank_by"] == "f1"
    assert config["observed"]["sim-chips"] == {
        "image_size": [[128, 128]],
        "pixel_spacing": [[0.3, 0.3]],
    }


def test_the_leaderboard_is_in_ranked_order_with_its_intervals(run):
    out, res = run
    page = Page((out / "report.html").read_text())
    assert len(page.boards) == 1  # one dataset
    summary = res.summary.sort_values("f1", ascending=False, kind="stable")
    assert _detectors(page.boards[0]) == summary.detector.tolist()
    for cells, (_, row) in zip(page.boards[0], summary.iterrows(), strict=True):
        assert f"{row.f1:.3f}" in cells[2]
        assert f"{row.f1_lo:.3f}–{row.f1_hi:.3f}" in cells[2]  # the 95 % interval
    # ranked by another metric, lower is better: false alarms per image, fewest first
    by_fa = Page(build_report([out], rank_by="false_alarms_per_image"))
    fewest = res.summary.sort_values("false_alarms_per_image", kind="stable").detector.tolist()
    assert _detectors(by_fa.boards[0]) == fewest


def test_every_figure_is_embedded(run):
    out, _ = run
    page = Page((out / "report.html").read_text())
    assert page.figures == 4  # FROC, precision-recall, pixel ROC, Pd vs SCR of the one dataset
    cases = pd.read_csv(out / "gallery" / "cases.csv")
    assert len(cases) > 0
    assert len(page.images) == len(cases)
    for src, f in zip(page.images, cases.file, strict=True):
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1]) == (out / f).read_bytes()


def test_the_page_is_offline_and_self_contained(run):
    out, _ = run
    text = (out / "report.html").read_text()
    page = Page(text)
    assert page.links, "expected in-page links"
    for link in page.links:
        assert link.startswith(("data:image/", "#")), link
    assert not {"script", "link", "iframe", "object"} & page.tags
    assert "@import" not in text and not re.search(r"url\((?!#)", text)
    ids = re.findall(r'\bid="([^"]+)"', text)
    assert len(ids) == len(set(ids))  # figures inline side by side keep unique ids
    assert {link[1:] for link in page.links if link.startswith("#")} <= set(ids)


def test_the_report_command_rebuilds_the_same_page(run, capsys):
    out, _ = run
    written = (out / "report.html").read_bytes()
    (out / "report.html").unlink()
    assert main(["report", str(out)]) == 0
    assert (out / "report.html").read_bytes() == written
    assert f"wrote {out / 'report.html'}" in capsys.readouterr().out


def test_the_dataset_card(run, tmp_path):
    out, _ = run
    text = (out / "report.html").read_text()
    for fact in (
        "intensity (power), used as is",
        "128 × 128 px",
        "0.3 × 0.3 m",
        "vehicle (4)",
        "prescreening rule",
        "200 replicates",
        "only 4 targets: intervals are wide",
    ):
        assert fact in text, fact
    assert "design Pfa is not meaningful" not in text
    copy = _copy(run, tmp_path)
    config = json.loads((copy / "config.json").read_text())
    config["options"]["datasets"]["sim-chips"]["sample_type"] = "display"
    (copy / "config.json").write_text(json.dumps(config))
    assert "design Pfa is not meaningful" in build_report([copy])


def test_notes_name_detectors_without_detections_and_identical_ones(run, tmp_path):
    copy = _copy(run, tmp_path)
    for name in ("summary.csv", "roc.csv", "timing.csv"):
        df = pd.read_csv(copy / name)
        twin = df[df.detector == "ca"].assign(detector="twin")
        pd.concat([df, twin], ignore_index=True).to_csv(copy / name, index=False)
    summary = pd.read_csv(copy / "summary.csv")
    summary.loc[summary.detector == "so", ["tp", "fp", "f1"]] = [0, 0, 0.0]
    summary.to_csv(copy / "summary.csv", index=False)
    board = Page(build_report([copy])).boards[0]
    notes = {cells[1].split(" ")[0]: cells[1] for cells in board}
    assert notes["twin"] == "twin identical results to ca"
    assert notes["so"] == f"so {NO_DETECTION}"
    assert notes["ca"] == "ca"
    assert _detectors(board).index("ca") < _detectors(board).index("twin")


def test_optional_tables_are_shown_when_present(run, tmp_path):
    copy = _copy(run, tmp_path)
    rows = [
        [
            "sim-chips",
            d,
            "measured",
            f"{c - 2.5:g}-{c + 2.5:g}",
            c - 2.5,
            c + 2.5,
            c,
            n,
            k,
            k / n,
            max(0, k / n - 0.2),
            min(1, k / n + 0.1),
        ]
        for d in ("ca", "so")
        for c, n, k in ((2.5, 5, 2), (7.5, 4, 3), (12.5, 6, 6))
    ]
    pd.DataFrame(rows, columns=SCR_COLUMNS).to_csv(copy / "scr.csv", index=False)
    pd.DataFrame(
        [
            ["sim-chips", "ca", "false_alarm", "fragment", 7],
            ["sim-chips", "ca", "false_alarm", "clutter", 3],
            ["sim-chips", "so", "false_alarm", "clutter", 11],
            ["sim-chips", "so", "miss", "size:small", 2],
        ],
        columns=["dataset", "detector", "error", "type", "count"],
    ).to_csv(copy / "errors.csv", index=False)
    pd.DataFrame(
        [["sim-chips", "so", "ca", "f1", -0.25, -0.4, -0.1, True]],
        columns=[
            "dataset",
            "detector",
            "reference",
            "metric",
            "difference",
            "lo",
            "hi",
            "significant",
        ],
    ).to_csv(copy / "paired.csv", index=False)
    text = build_report([copy])
    page = Page(text)
    assert page.figures == 4 and "Pd vs SCR" in text
    assert "False alarms by type" in text and "fragment" in text and ">11<" in text
    assert "Missed targets by size and SCR" in text and "size:small" in text
    fa_part = text.split("False alarms by type")[1].split("Missed targets")[0]
    assert "size:small" not in fa_part  # the families are apart
    assert "Paired differences" in text and "-0.25" in text and "<b>yes</b>" in text
    # tables of another shape: no crash, what cannot be read is skipped
    scr = pd.read_csv(copy / "scr.csv").rename(columns={"scr_mean_db": "scr_db"})
    scr.drop(columns=["pd_lo", "pd_hi"]).to_csv(copy / "scr.csv", index=False)
    pd.DataFrame({"dataset": ["sim-chips"], "detector": ["so"], "delta": [0.1]}).to_csv(
        copy / "paired.csv", index=False
    )
    pd.DataFrame({"dataset": ["sim-chips"], "what": ["x"]}).to_csv(copy / "errors.csv", index=False)
    page = Page(build_report([copy]))
    assert page.figures == 3  # no Pd-vs-SCR figure without its columns


def test_an_old_run_without_gallery_or_config_is_reported(run, tmp_path):
    copy = _copy(run, tmp_path)
    shutil.rmtree(copy / "gallery")
    (copy / "config.json").unlink()
    (copy / "report.html").unlink()
    assert main(["report", str(copy)]) == 0
    page = Page((copy / "report.html").read_text())
    assert len(page.boards) == 1 and page.figures == 4 and not page.images


def test_two_runs_compared_in_one_page(run, other, tmp_path):
    out = tmp_path / "both.html"
    assert main(["report", str(run[0]), str(other), "--out", str(out)]) == 0
    text = out.read_text()
    page = Page(text)
    board = page.boards[0]
    assert len(board) == 4
    runs = [cells[2] for cells in board]
    assert sorted(runs) == ["a", "a", "b", "b"]
    labels = {(cells[1].split(" ")[0], cells[2]): cells[1] for cells in board}
    # ca scored twice on the same images: the lower row says so
    assert labels[("ca", "b")] == "ca identical results to ca (a)"
    assert "ca (a)" in text and "vi (b)" in text
    assert page.figures == 4
    for d in ("ca", "so", "vi"):
        assert detector_colour(d) in text
    # several runs need --out, and a bad metric or folder is one error line
    assert main(["report", str(run[0]), str(other)]) == 2
    assert main(["report", str(run[0]), "--rank-by", "speed"]) == 2
    assert main(["report", str(tmp_path)]) == 2
    assert main(["report", str(run[0]), "--out", str(tmp_path / "page.txt")]) == 2


def test_rank_by_is_checked_before_any_work(tmp_path):
    with pytest.raises(EvalError, match=r"rank_by='speed': not a metric"):
        te.evaluate("sim-chips", ["ca"], n=1, out=tmp_path / "x", rank_by="speed")
    assert not (tmp_path / "x").exists()


def test_detector_colours_are_stable_and_distinct():
    colours = [detector_colour(n) for n in BUILTIN]
    assert len(set(colours)) == len(colours)  # every built-in its own colour
    for name in ["mine", "pkg.mod:Det", "ca (b)", ""]:
        assert detector_colour(name) in PALETTE and detector_colour(name) == detector_colour(name)
        assert detector_colour(name) not in colours  # never a built-in's colour
        assert detector_dash(name) in ("--", "-.", ":")
    assert all(re.fullmatch(r"#[0-9a-f]{6}", c) for c in PALETTE)


def test_the_report_embeds_only_figures_inside_the_run_folder(run, tmp_path):
    """Paths a run's ``gallery/cases.csv`` names, and figures that are links, FIFOs or not
    PNGs, are never read into the page: nothing of the machine outside the run folder."""
    import os

    copy = _copy(run, tmp_path)
    secret = tmp_path / "secret.png"
    secret.write_bytes(b"\x89PNG\r\n\x1a\n" + b"SECRET-OUTSIDE-THE-RUN" * 8)
    inside = copy / "gallery" / "inside.png"
    inside.write_bytes(b"\x89PNG\r\n\x1a\n" + b"A-FIGURE-OF-THE-RUN" * 8)
    (copy / "gallery" / "link.png").symlink_to(secret)
    (copy / "linked.png").symlink_to(secret)
    os.mkfifo(copy / "gallery" / "fifo.png")
    (copy / "gallery" / "text.png").write_text("not a png")
    cases = pd.read_csv(copy / "gallery" / "cases.csv")
    row = cases.iloc[0]
    names = [
        str(secret),
        "../" * 12 + str(secret)[1:],
        "gallery/link.png",
        "gallery/fifo.png",
        "gallery/text.png",
        "/dev/zero",
        "gallery/inside.png",
    ]
    pd.concat([pd.DataFrame([{**row.to_dict(), "file": n} for n in names]), cases]).to_csv(
        copy / "gallery" / "cases.csv", index=False
    )
    assert main(["report", str(copy)]) == 0
    text = (copy / "report.html").read_text()
    embedded = b"".join(
        base64.b64decode(src.split(",", 1)[1])
        for src in Page(text).images
        if src.startswith("data:")
    )
    assert b"SECRET-OUTSIDE-THE-RUN" not in embedded
    assert b"A-FIGURE-OF-THE-RUN" in embedded
    # a table that is a link out of the run is not read either
    outside = tmp_path / "errors.csv"
    outside.write_text("dataset,detector,kind,key,count\nSECRET-TABLE,x,fa,y,1\n")
    (copy / "errors.csv").unlink(missing_ok=True)
    (copy / "errors.csv").symlink_to(outside)
    assert main(["report", str(copy)]) == 0
    assert "SECRET-TABLE" not in (copy / "report.html").read_text()


def test_pd_vs_scr_points_sit_at_their_bins_mean_scr(run):
    """The drawn points of the Pd-vs-SCR figure (read back from the figure's lines) are at
    each bin's ``scr_mean_db``, never at a number parsed from the bin's label."""
    import matplotlib.pyplot as plt
    import numpy as np

    from torchsar_eval.panels import Curve, draw_panel

    scr = run[1].scr
    series = [Curve(d, d, detector_colour(d), "-") for d in scr.detector.unique()]
    fig, ax = plt.subplots()
    assert not draw_panel(ax, "scr", scr, series)  # no detector left out
    for s in series:
        (line,) = [ln for ln in ax.lines if ln.get_gid() == f"scr-line-{s.label}"]
        assert line.get_color() == s.colour and line.get_marker() == s.style()["marker"]
        assert line.get_markerfacecolor() != "none"  # filled: the measured SCR
        rows = scr[(scr.detector == s.detector) & (scr.source == "measured") & scr.pd.notna()]
        want = sorted(zip(rows.scr_mean_db, rows.pd, strict=True))
        assert list(zip(line.get_xdata(), line.get_ydata(), strict=True)) == want
        lo, hi = rows.scr_lo_db.to_numpy(), rows.scr_hi_db.to_numpy()
        assert ((rows.scr_mean_db >= lo) & (rows.scr_mean_db < hi)).all()
    plt.close(fig)
    assert np.isfinite(scr.scr_mean_db[scr.targets > 0]).all()


def test_pd_vs_scr_labels_with_negative_looking_bins_are_not_parsed():
    """'5-10' is the bin [5, 10): its point sits at the targets' mean SCR (7.5 here)."""
    from torchsar_eval.panels import scr_points

    d = pd.DataFrame(
        {
            "source": ["measured"] * 3,
            "scr_bin": ["5-10", "10-15", "15-20"],
            "scr_lo_db": [5.0, 10.0, 15.0],
            "scr_hi_db": [10.0, 15.0, 20.0],
            "scr_mean_db": [7.5, 12.0, 16.0],
            "pd": [0.2, 0.6, 0.9],
            "pd_lo": [0.1, 0.4, 0.7],
            "pd_hi": [0.4, 0.8, 1.0],
        }
    )
    ((source, x, y, _),) = scr_points(d)
    assert source == "measured"
    assert x.tolist() == [7.5, 12.0, 16.0] and y.tolist() == [0.2, 0.6, 0.9]


def test_every_leaderboard_row_says_what_it_measured(run):
    out, res = run
    page = Page((out / "report.html").read_text())
    summary = res.summary.set_index("detector")
    for cells in page.boards[0]:
        row = summary.loc[cells[1].split(" ")[0]]
        assert row.iou_type == "mask" and cells[-1] == "mask IoU"
        assert "AP: mask IoU" in row.matching
    assert all(
        f'title="{m}"' in (out / "report.html").read_text().replace("&lt;", "<")
        for m in summary.matching
    )


def test_every_case_says_why_it_is_one(run):
    from torchsar.metrics.reasons import FA_WORDS

    out, _ = run
    cases = pd.read_csv(out / "gallery" / "cases.csv")
    assert len(cases) and cases.why.notna().all()
    fa = cases[cases.kind == "false_alarm"]
    assert all(any(w.startswith(v) for v in FA_WORDS.values()) for w in fa.why)
    text = (out / "report.html").read_text()
    for why in cases.why:
        assert why.replace("'", "&#x27;").replace(">", "&gt;").replace("<", "&lt;") in text


def test_the_pr_legend_gives_each_curve_its_ap(run):
    import matplotlib.pyplot as plt

    from torchsar_eval.panels import Curve, draw_panel

    _, res = run
    rows = {r.detector: r for _, r in res.summary.iterrows()}
    series = [Curve(d, d, detector_colour(d), "-", rows[d]) for d in rows]
    fig, ax = plt.subplots()
    left = draw_panel(ax, "pr", res.pr, series)
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    drawn = [d for d in rows if not res.pr[res.pr.detector == d].empty and rows[d].ap50 > 0]
    assert texts == [f"{d} (AP50 {rows[d].ap50:.3f})" for d in drawn]
    assert set(left) == set(rows) - set(drawn)  # the rest named in the title
    plt.close(fig)


def test_datasets_are_headed_by_short_names(run, tmp_path):
    """A dataset named by its full path is headed by its last path part (the full name in the
    heading's title and the card)."""
    copy = _copy(run, tmp_path)
    long = "folder:/very/long/absolute/path/to/the/data/chips"
    for name in ("summary", "timing", "froc", "pr", "breakdown", "scr", "errors", "paired"):
        f = copy / f"{name}.csv"
        if f.exists():
            df = pd.read_csv(f)
            if "dataset" in df.columns:
                df.assign(dataset=long).to_csv(f, index=False)
    text = build_report([copy])
    assert f'<h2 title="{long}">folder:chips</h2>' in text
    assert f">{long}<" not in text.split("<main>")[0]  # not in the header or the nav


def test_ap_by_size_is_in_the_report(run):
    out, res = run
    text = (out / "report.html").read_text()
    assert "AP by size and class" in text
    section = text.split("AP by size and class")[1].split("</table>")[0]
    for _, row in res.summary.iterrows():
        assert f"{row.ap50_95:.3g}" in section or row.ap50_95 == 0
