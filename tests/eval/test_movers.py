"""``torchsar-eval movers`` on a reduced system: files, columns, the aliased mover found."""

from __future__ import annotations

import json

import pandas as pd

from eval.cli import main
from eval.commands.movers import SHOWN


def test_movers_small_ladder(tmp_path, capsys):
    out = tmp_path / "mv"
    argv = ["movers", "--size", "256", "--azimuth-resolution", "1.0", "--speeds", "0.39,2.34"]
    code = main([*argv, "--directions", "range", "--out", str(out), "--no-progress"])
    assert code == 0
    names = {p.name for p in out.iterdir()}
    assert {"movers.csv", "movers.md", "config.json", "ladder.png", "pairs_range.png"} <= names
    table = pd.read_csv(out / "movers.csv")
    assert set(SHOWN) <= set(table.columns)
    assert table.speed_mps.tolist() == [0.39, 2.34]
    assert (table.stationary_found == 3).all()
    fast = table[table.speed_mps == 2.34].iloc[0]
    assert fast.detected_corrected and fast.false_movers_corrected == 0
    assert abs(fast.measured_shift_corrected_m - fast.theory_shift_corrected_m) < 0.1
    assert abs(fast.measured_shift_m - fast.theory_shift_m) < 0.1
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["options"]["derived"]["n_pulses"] == 150
    assert "PRF 200 Hz" in capsys.readouterr().out


def test_movers_rejects_bad_directions(tmp_path):
    try:
        main(["movers", "--directions", "up", "--out", str(tmp_path / "x"), "--no-progress"])
    except SystemExit as exc:
        assert "directions" in str(exc)
    else:
        raise AssertionError("expected SystemExit")
