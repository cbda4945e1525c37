"""End-to-end test of ``torchsar-eval compare-region`` on tiny settings."""

from __future__ import annotations

import pandas as pd
import pytest

from torchsar_eval.cli import main


def test_compare_region_tiny(tmp_path, capsys):
    pytest.importorskip("torchsar.speckle", reason="needs torchsar.speckle (enhanced Frost)")
    out = tmp_path / "out"
    code = main(
        [
            "compare-region",
            "--out",
            str(out),
            "--sim",
            "sim-chips",
            "--n",
            "2",
            "--n-tune",
            "1",
            "--mstar",
            str(tmp_path / "absent"),
            "--guards",
            "4",
            "--trains",
            "4",
            "--pfas",
            "1e-4",
            "--no-progress",
        ]
    )
    assert code == 0
    summary = pd.read_csv(out / "summary.csv")
    assert {"region-paper", "region", "ca", "two_parameter"} <= set(summary.detector)
    assert set(summary.dataset) == {"sim-chips"}
    chosen = pd.read_csv(out / "chosen.csv")
    assert set(chosen.guard) == {4}
    assert (out / "panel_sim-chips.png").stat().st_size > 0
    text = capsys.readouterr().out
    assert "not found: skipped" in text
