"""``torchsar-eval movers`` at a tiny size: files, columns, a mover found, one-line errors."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from torchsar_eval.cli import main
from torchsar_eval.experiments.movers.experiment import SHOWN

TINY = ["--size", "256", "--azimuth-resolution", "1.0", "--clutter-points", "60", "--no-progress"]


def test_movers_tiny_ladder(tmp_path, capsys):
    out = tmp_path / "mv"
    argv = ["movers", *TINY, "--speeds", "9.36", "--snr-ladder", "", "--controls", "1"]
    assert main([*argv, "--out", str(out)]) == 0
    names = {p.name for p in out.iterdir()}
    assert {
        "movers.csv",
        "movers.md",
        "sensitivity.csv",
        "config.json",
        "displacement.png",
    } <= names
    table = pd.read_csv(out / "movers.csv")
    assert set(SHOWN) <= set(table.columns)
    assert table.kind.tolist() == ["ladder", "ladder", "control"]
    along = table[table.direction == "along-track"].iloc[0]
    assert along.mover_found and along.look_detected
    assert abs(along.look_shift_m - along.theory_look_shift_m) < 0.1 * along.theory_look_shift_m
    assert table.combined_false_stationary.sum() == 0 and table.combined_false_clutter.sum() == 0
    radial = table[table.direction == "range"].iloc[0]
    assert radial.theory_fold == -3 and not radial.combined_detected
    # 64 range pixels over 180 m undersample the 1 m resolution: no walk, nothing radial
    assert not table.radial_detected.any() and table.radial_false_clutter.sum() == 0
    assert (table.stationary_found == 3).all()
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["options"]["derived"]["n_pulses"] == 150
    printed = capsys.readouterr().out
    assert "Radial (range) motion" in printed and "minimum detectable" in printed


@pytest.mark.parametrize(
    "argv,message",
    [
        (["--speeds", "abc"], "--speeds must be comma-separated numbers"),
        (["--speeds", "nan"], "--speeds must be finite"),
        (["--speeds", "-1"], "--speeds must be > 0"),
        (["--snr-ladder", "x"], "--snr-ladder must be"),
        (["--directions", "up"], "--directions"),
        (["--looks", "9"], "--looks in 2..4"),
        (["--max-fold", "-1"], "--max-fold"),
    ],
)
def test_bad_options_exit_2_with_one_line(tmp_path, capsys, argv, message):
    out = tmp_path / "x"
    assert main(["movers", *argv, "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("torchsar-eval: error: ") and message in err[0]
    assert not out.exists()
