"""``summary.tex``: the numbers of ``summary.csv`` as booktabs tables, intervals as
``x [lo, hi]``, the best of each column in bold; it compiles where pdflatex is installed."""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest

import torchsar_eval as te
from torchsar_eval.latex import COLUMNS, escape, number, summary_tex
from torchsar_eval.leaderboard import LOWER_IS_BETTER


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("tex") / "run"
    res = te.evaluate(
        "sim-chips",
        ["ca", "so", "os"],
        n=4,
        out=out,
        progress=False,
        scoring=te.Scoring(replicates=40),
    )
    return out, res


def _rows(tex: str) -> dict[str, list[str]]:
    body = tex.split(r"\midrule")[1].split(r"\bottomrule")[0]
    rows = [line.rstrip(" \\").split(" & ") for line in body.strip().splitlines()]
    return {r[0]: r[1:] for r in rows}


def test_the_table_holds_the_numbers_of_summary_csv(run):
    out, _ = run
    tex = (out / "summary.tex").read_text()
    summary = pd.read_csv(out / "summary.csv")
    metrics = [m for m, _ in COLUMNS if summary[m].notna().any()]
    rows = _rows(tex)
    assert set(rows) == set(summary.detector)
    for _, row in summary.iterrows():
        for m, cell in zip(metrics, rows[row.detector], strict=True):
            value = re.sub(r"\\textbf\{([^}]*)\}", r"\1", cell)
            want = number(m, row[m])
            if np.isfinite(row[f"{m}_lo"]):
                want += f" {{\\footnotesize [{number(m, row[f'{m}_lo'])}, {number(m, row[f'{m}_hi'])}]}}"
            assert value == want


def test_the_best_of_each_column_is_bold_and_only_it(run):
    out, _ = run
    tex = (out / "summary.tex").read_text()
    summary = pd.read_csv(out / "summary.csv")
    metrics = [m for m, _ in COLUMNS if summary[m].notna().any()]
    rows = _rows(tex)
    for k, m in enumerate(metrics):
        printed = {
            d: float(number(m, v)) for d, v in zip(summary.detector, summary[m], strict=True)
        }
        best = min(printed.values()) if m in LOWER_IS_BETTER else max(printed.values())
        for d, cells in rows.items():
            assert cells[k].startswith(r"\textbf{") == (printed[d] == best), (m, d)


def test_rows_follow_the_leaderboard_and_the_rule_is_stated(run):
    out, res = run
    tex = (out / "summary.tex").read_text()
    ranked = res.summary.sort_values("f1", ascending=False, kind="stable").detector.tolist()
    assert list(_rows(tex)) == ranked
    assert escape(res.summary.matching.iloc[0]) in tex
    assert r"\usepackage{booktabs}" in tex and tex.count(r"\begin{table}") == 1


def test_names_are_escaped():
    s = pd.DataFrame(
        {
            "dataset": ["ships_2&3"],
            "detector": ["my_det%"],
            "images": [1],
            "targets": [1],
            "matching": ["box IoU >= 0.5"],
            "f1": [0.5],
        }
    )
    tex = summary_tex(s)
    assert r"my\_det\%" in tex and r"ships\_2\&3" in tex and r"\textgreater{}=" in tex


@pytest.mark.skipif(shutil.which("pdflatex") is None, reason="pdflatex is not installed")
def test_summary_tex_compiles(run, tmp_path):
    out, _ = run
    doc = tmp_path / "doc.tex"
    doc.write_text(
        "\\documentclass{article}\\usepackage{booktabs}\\begin{document}\n"
        + (out / "summary.tex").read_text()
        + "\\end{document}\n"
    )
    done = subprocess.run(
        ["pdflatex", "-interaction=nonstopmode", "-halt-on-error", doc.name],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stdout[-2000:]
    assert (tmp_path / "doc.pdf").stat().st_size > 0
