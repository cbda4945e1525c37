"""``figures=False`` / ``--no-figures``: the same tables and summaries without curves, gallery
or page; the page built later from the folder; the environment's default."""

from __future__ import annotations

import json

import pytest

import torchsar_eval as te
from torchsar_eval.cli import main
from torchsar_eval.errors import EvalError

TABLES = (
    "summary.csv",
    "per_image.csv",
    "summary.tex",
    "roc.csv",
    "pr.csv",
    "errors.csv",
    "scr.csv",
)


def _run(out, **kw):
    return te.evaluate("sim-chips", ["ca", "os"], n=4, out=out, progress=False, **kw)


@pytest.mark.figures
def test_no_figures_writes_the_same_tables_and_no_picture(tmp_path):
    with_figures = _run(tmp_path / "a", figures=True)
    without = _run(tmp_path / "b", figures=False)
    for name in TABLES:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    untimed = [(tmp_path / r / "summary.md").read_text().split("## Timing")[0] for r in "ab"]
    assert untimed[0] == untimed[1]
    drawn = {p.name for p in (tmp_path / "a").iterdir()}
    kept = {p.name for p in (tmp_path / "b").iterdir()}
    assert {"report.html", "gallery"} <= drawn and any(n.endswith(".png") for n in drawn)
    assert "report.html" not in kept and "gallery" not in kept
    assert not any(n.endswith((".png", ".pdf")) for n in kept)
    assert set(without.files) <= kept and "report.html" in with_figures.files
    assert json.loads((tmp_path / "b" / "config.json").read_text())["options"]["figures"] is False


@pytest.mark.figures
def test_the_page_is_built_later_from_the_tables(tmp_path, capsys):
    _run(tmp_path / "b", figures=False)
    assert main(["report", str(tmp_path / "b")]) == 0
    page = (tmp_path / "b" / "report.html").read_text()
    assert "ca" in page and "<svg" in page


def test_the_environment_sets_the_default_and_the_option_wins(tmp_path, monkeypatch):
    monkeypatch.setenv("TORCHSAR_EVAL_FIGURES", "0")
    _run(tmp_path / "env")
    assert not (tmp_path / "env" / "report.html").exists()
    monkeypatch.setenv("TORCHSAR_EVAL_FIGURES", "1")
    out = tmp_path / "cli"
    args = ["run", "--dataset", "sim-chips", "--detectors", "ca", "--n", "2", "--out", str(out)]
    assert main([*args, "--no-figures"]) == 0
    assert not (out / "report.html").exists() and (out / "summary.csv").exists()


def test_a_figures_value_that_is_not_a_flag_is_refused(tmp_path):
    with pytest.raises(EvalError, match="figures"):
        _run(tmp_path / "x", figures="no")
