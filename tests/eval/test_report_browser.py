"""``report.html`` in a real browser (headless Chromium, network off): it loads without a
console message, every image decodes, the leaderboard and every figure are laid out with a
size, and a screenshot shows them.

Slow (a run and a few browser starts): run with ``pytest -m slow tests/eval/test_report_browser.py``.
Skipped when no Chromium is installed (Debian: ``apt-get install chromium``; any other
binary: set ``TORCHSAR_BROWSER``)."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess

import numpy as np
import pytest
from PIL import Image

import torchsar_eval as te
from torchsar_eval.colours import detector_colour
from torchsar_eval.html_report.figures import FIGURES

pytestmark = [pytest.mark.slow, pytest.mark.figures]  # pages in a browser

NAMES = ["chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome"]
WIDTH, HEIGHT = 1366, 2600


def _browser() -> str:
    found = os.environ.get("TORCHSAR_BROWSER") or next(filter(None, map(shutil.which, NAMES)), None)
    if not found:
        pytest.skip("no Chromium installed (apt-get install chromium, or set TORCHSAR_BROWSER)")
    return found


def _chromium(tmp_path, *args: str) -> subprocess.CompletedProcess:
    """Headless Chromium with its own profile, no network (every host unresolvable)."""
    argv = [
        _browser(),
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--hide-scrollbars",
        f"--user-data-dir={tmp_path / 'profile'}",
        "--host-resolver-rules=MAP * ~NOTFOUND",
        "--enable-logging=stderr",
        "--v=0",
        "--virtual-time-budget=5000",
        *args,
    ]
    return subprocess.run(argv, capture_output=True, text=True, timeout=180, cwd=tmp_path)


PROBE = """<script>
window.__errors = [];
window.addEventListener("error", e => window.__errors.push(String(e.message || e.type)), true);
window.addEventListener("load", () => {
  const size = el => { const b = el.getBoundingClientRect(); return [b.width, b.height]; };
  const board = document.querySelector("table.leaderboard");
  const r = {errors: window.__errors,
             images: [...document.images].map(i => [i.naturalWidth, ...size(i)]),
             figures: [...document.querySelectorAll("svg.fig")].map(size),
             board: board ? [...size(board), board.tBodies[0].rows.length] : null};
  const pre = document.createElement("pre");
  pre.id = "probe";
  pre.textContent = JSON.stringify(r);
  document.body.appendChild(pre);
});
</script>"""


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    _browser()  # skip before the run when there is no browser
    out = tmp_path_factory.mktemp("browser") / "run"
    te.evaluate("sim-chips", ["ca", "so"], n=4, out=out, progress=False)
    return out / "report.html"


def test_the_report_loads_without_console_messages(report, tmp_path):
    done = _chromium(tmp_path, "--dump-dom", report.as_uri())
    assert done.returncode == 0, done.stderr[-2000:]
    console = [line for line in done.stderr.splitlines() if ":CONSOLE" in line]
    assert not console, console
    assert 'class="leaderboard"' in done.stdout


def test_leaderboard_figures_and_images_are_laid_out(report, tmp_path):
    probe = tmp_path / "probe.html"
    probe.write_text(report.read_text().replace("<head>", "<head>" + PROBE, 1))
    done = _chromium(tmp_path, f"--window-size={WIDTH},{HEIGHT}", "--dump-dom", probe.as_uri())
    found = re.search(r'<pre id="probe">(.*?)</pre>', done.stdout, re.S)
    assert found, done.stderr[-2000:]
    r = json.loads(found.group(1).replace("&quot;", '"').replace("&amp;", "&"))
    assert r["errors"] == []
    width, height, rows = r["board"]
    assert width > 300 and height > 0 and rows == 2
    assert len(r["figures"]) == len(FIGURES)  # sim-chips fills every figure
    assert all(w > 100 and h > 100 for w, h in r["figures"])
    assert r["images"] and all(n > 0 and w > 0 and h > 0 for n, w, h in r["images"])


def test_a_screenshot_shows_the_page(report, tmp_path):
    shot = tmp_path / "shot.png"
    done = _chromium(
        tmp_path, f"--window-size={WIDTH},{HEIGHT}", f"--screenshot={shot}", report.as_uri()
    )
    assert shot.is_file(), done.stderr[-2000:]
    with Image.open(shot) as im:
        rgb = np.asarray(im.convert("RGB")).astype(int)
    assert rgb.shape[:2] == (HEIGHT, WIDTH)
    ink = (rgb < 200).any(axis=-1).mean()
    assert 0.02 < ink < 0.9, ink  # neither blank nor one block of colour
    for name in ("ca", "so"):  # the detectors' own colours are drawn (swatches, curves)
        want = np.array([int(detector_colour(name)[i : i + 2], 16) for i in (1, 3, 5)])
        assert (np.abs(rgb - want).max(axis=-1) <= 8).sum() > 50, name


COMPARE_PROBE = """<script>
window.addEventListener("load", () => {
  const rect = el => { const b = el.getBoundingClientRect();
                       return [b.left, b.top, b.right, b.bottom]; };
  const wraps = [...document.querySelectorAll("table.leaderboard")].map(t => {
    const w = t.closest(".wrap");
    return [w.scrollWidth, w.clientWidth, t.getBoundingClientRect().right]; });
  const cells = [...document.querySelectorAll("table.leaderboard td.rule")].map(
    td => td.textContent.trim());
  const cases = [...document.querySelectorAll("figure.case")].map(f => [
    rect(f), rect(f.querySelector("figcaption")), rect(f.querySelector("img"))]);
  const pre = document.createElement("pre");
  pre.id = "probe";
  pre.textContent = JSON.stringify({wraps, cells, cases, width: window.innerWidth});
  document.body.appendChild(pre);
});
</script>"""


def _boxes(images):
    """A box detector: one box around each chip's brightest pixel (score: its dB)."""
    import torch

    from torchsar.objects import Objects

    b, _, h, w = images.shape
    flat = images[:, 0].reshape(b, -1)
    peak = flat.argmax(dim=1)
    r, c = (peak // w).double(), (peak % w).double()
    boxes = torch.stack([r - 4, c - 4, r + 5, c + 5], 1).clamp(min=0).numpy()
    boxes[:, 2:] = np.minimum(boxes[:, 2:], [h, w])
    return Objects.from_boxes(
        boxes,
        torch.log10(flat.max(dim=1).values).numpy(),
        shape=(h, w),
        plane=np.arange(b),
        planes=b,
    )


@pytest.fixture(scope="module")
def compared(tmp_path_factory):
    """Two runs of a CFAR, a box detector and a predictions file, the CFAR with other
    options in the second, compared in one page."""
    _browser()
    root = tmp_path_factory.mktemp("compare")
    base = te.evaluate("sim-chips", ["ca"], n=6, progress=False, scoring=te.Scoring(replicates=0))
    pts = root / "points.csv"
    pts.write_text(
        "image,row,col,score\n"
        + "".join(f"{im},64,64,0.7\n{im},10,100,0.2\n" for im in base.per_image.image)
    )
    runs = []
    for name, pfa in (("a", 1e-3), ("b", 1e-6)):
        dets = {
            "ca": te.load("ca", options={"pfa": pfa}),
            "boxes": te.Detector("boxes", _boxes),
            "points": te.predictions(pts, name="points"),
        }
        te.evaluate(
            "sim-chips",
            dets,
            n=6,
            out=root / name,
            progress=False,
            scoring=te.Scoring(replicates=50),
        )
        runs.append(root / name)
    page = root / "compare.html"
    from torchsar_eval.html_report import write_report

    write_report(runs, page)
    return page


def test_the_compare_page_fits_and_says_what_each_row_measured(compared, tmp_path):
    probe = tmp_path / "probe.html"
    probe.write_text(compared.read_text().replace("<head>", "<head>" + COMPARE_PROBE, 1))
    done = _chromium(tmp_path, "--window-size=1366,2600", "--dump-dom", probe.as_uri())
    found = re.search(r'<pre id="probe">(.*?)</pre>', done.stdout, re.S)
    assert found, done.stderr[-2000:]
    r = json.loads(found.group(1).replace("&quot;", '"').replace("&amp;", "&"))
    for scroll, client, right in r["wraps"]:  # no horizontal scroll, nothing past the window
        assert scroll <= client + 1 and right <= r["width"], (scroll, client, right)
    assert len(r["cells"]) == 6
    assert set(r["cells"]) == {"mask IoU", "box IoU", "point: no AP"}  # CFAR, boxes, points
    boxes = [c[0] for c in r["cases"]]
    for i, a in enumerate(boxes):  # no caption (no tile) overlaps another
        for b in boxes[i + 1 :]:
            assert (
                a[2] <= b[0] + 0.5 or b[2] <= a[0] + 0.5 or a[3] <= b[1] + 0.5 or b[3] <= a[1] + 0.5
            ), (a, b)
    for tile, caption, _ in r["cases"]:  # each caption inside its tile
        assert tile[0] - 0.5 <= caption[0] and caption[2] <= tile[2] + 0.5


SCR_PROBE = """<script>
window.addEventListener("load", () => {
  const mid = el => { const b = el.getBoundingClientRect(); return (b.left + b.right) / 2; };
  const svg = [...document.querySelectorAll("svg.fig")].find(
    s => (s.getAttribute("aria-label") || "").startsWith("Pd vs SCR"));
  const ticks = [...svg.querySelectorAll('g[id*="xtick_"]')].map(
    g => [mid(g.querySelector("use")), g.querySelector("text").textContent]);
  const lines = {};
  for (const g of svg.querySelectorAll('g[id*="scr-line-"]'))
    lines[g.id.split("scr-line-")[1]] = [...g.querySelectorAll("use")].map(mid);
  const pre = document.createElement("pre");
  pre.id = "probe";
  pre.textContent = JSON.stringify({ticks, lines});
  document.body.appendChild(pre);
});
</script>"""


def test_scr_points_sit_at_their_bins_mean_scr(compared, tmp_path):
    """The Pd-vs-SCR markers as the browser lays them out, read back in dB through the
    axis' own tick marks, are each detector's bins' mean SCR from ``scr.csv``."""
    import pandas as pd

    run = compared.parent / "a"
    probe = tmp_path / "probe.html"
    probe.write_text((run / "report.html").read_text().replace("<head>", "<head>" + SCR_PROBE, 1))
    done = _chromium(tmp_path, "--window-size=1366,2600", "--dump-dom", probe.as_uri())
    found = re.search(r'<pre id="probe">(.*?)</pre>', done.stdout, re.S)
    assert found, done.stderr[-2000:]
    r = json.loads(found.group(1).replace("&quot;", '"').replace("&amp;", "&"))
    px = np.array([t[0] for t in r["ticks"]])
    db = np.array([float(t[1].replace("\u2212", "-")) for t in r["ticks"]])
    slope, offset = np.polyfit(db, px, 1)  # screen x of a dB value on this axis
    assert np.abs(slope * db + offset - px).max() < 0.5  # a linear axis
    scr = pd.read_csv(run / "scr.csv")
    measured = scr[scr["source"] == "measured"]
    drawn = measured.dropna(subset=["pd"])
    assert set(r["lines"]) == set(drawn["detector"]) == {"ca", "boxes", "points"}
    for det, xs in r["lines"].items():
        want = np.sort(drawn[drawn["detector"] == det]["scr_mean_db"].to_numpy())
        got = np.sort((np.array(xs) - offset) / slope)
        assert got.size == want.size > 0, det
        # within a tenth of a dB (a fraction of a screen pixel at this axis' scale)
        np.testing.assert_allclose(got, want, atol=max(0.1, 1 / abs(slope)))
