"""``summary.md`` carries the same leaderboard as ``report.html``: per dataset, detectors
best first by the ranking metric (ties share a rank), a note beside a detector with no
detection or with the same results as one above it, and the dataset's caveats."""

from __future__ import annotations

import math

import numpy as np
import pytest

import torchsar_eval as te
from tests.io.writers import write_png
from torchsar_eval.leaderboard import NO_DETECTION


def _board(text: str, dataset: str) -> tuple[list[dict], list[str]]:
    """The ranked table of ``dataset`` in ``summary.md`` as dicts, and its caveat lines."""
    lines = text.split(f"## {dataset}: ranked by", 1)[1].splitlines()[1:]
    table = [ln for ln in lines[: lines.index("", 2)] if ln.startswith("|")]
    head = [c.strip() for c in table[0].strip("|").split("|")]
    rows = [
        dict(zip(head, (c.strip() for c in ln.strip("|").split("|")), strict=True))
        for ln in table[2:]
    ]
    rest = lines[lines.index("", 2) :]
    bullets = []
    for ln in rest[1:]:
        if not ln.startswith("- "):
            break
        bullets.append(ln[2:])
    return rows, bullets


def _value(cell: str) -> float:
    v = float(cell.split(" [")[0])
    return -math.inf if math.isnan(v) else v


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("md") / "run"
    te.evaluate("sim-chips", ["lognormal", "so", "gamma", "ca"], n=6, out=out, progress=False)
    return out


def test_rows_are_ranked_by_f1_with_notes(run):
    rows, caveats = _board((run / "summary.md").read_text(), "sim-chips")
    f1 = [_value(r["f1"]) for r in rows]
    assert f1 == sorted(f1, reverse=True)
    by = {r["detector"]: r for r in rows}
    assert by["lognormal"]["note"] == NO_DETECTION and by["lognormal"]["rank"] == "4"
    # gamma at one look is CA: same results, same rank; ties keep the run's order (gamma
    # first here), the second of the two is noted
    assert [r["detector"] for r in rows].index("gamma") < [r["detector"] for r in rows].index("ca")
    assert by["ca"]["note"] == "identical results to gamma" and by["gamma"]["note"] == ""
    assert by["gamma"]["rank"] == by["ca"]["rank"]
    assert "only 6 targets: intervals are wide" in caveats
    assert any("identical" in c for c in caveats)


def test_rank_by_a_lower_is_better_metric(tmp_path):
    out = tmp_path / "run"
    te.evaluate(
        "sim-chips", ["so", "ca"], n=4, out=out, progress=False, rank_by="false_alarms_per_image"
    )
    text = (out / "summary.md").read_text()
    assert "ranked by false_alarms_per_image (lower is better)" in text
    rows, _ = _board(text, "sim-chips")
    fa = [float(r["false_alarms_per_image"].split(" [")[0]) for r in rows]
    assert fa == sorted(fa)


def test_display_data_carry_their_caveat(tmp_path):
    rng = np.random.default_rng(1)
    for i in range(3):
        img = rng.integers(0, 60, (48, 48), dtype=np.uint8)
        img[20:24, 20:24] = 250
        mask = np.zeros((48, 48), np.uint8)
        mask[20:24, 20:24] = 1
        write_png(tmp_path / f"c{i}.png", img)
        write_png(tmp_path / f"c{i}.mask.png", mask)
    out = tmp_path / "run"
    with pytest.warns(UserWarning):
        te.evaluate(f"folder:{tmp_path}", ["ca"], out=out, progress=False)
    text = (out / "summary.md").read_text()
    assert "display data (8/16-bit renderings of unknown transfer)" in text
