from __future__ import annotations

import json

import pandas as pd

from eval.cli import main


def test_autofocus_command_writes_tables(tmp_path):
    out = tmp_path / "af"
    code = main(
        [
            "autofocus",
            "--out",
            str(out),
            "--scenes",
            "2",
            "--size",
            "16",
            "--errors",
            "1d-uniform-pi,2d-3pi/4",
            "--methods",
            "conventional,sparse-autofocus",
            "--no-progress",
            "--no-gotcha",
        ]
    )
    assert code == 0
    table = pd.read_csv(out / "autofocus.csv")
    assert len(table) == 4
    assert {"corr_mean", "corr_std", "phase_rmse_mean", "success_mean", "seconds_mean"} <= set(
        table.columns
    )
    assert (table["scenes"] == 2).all()
    det = pd.read_csv(out / "detection.csv")
    assert {"pd_ca_mean", "pfa_ca_mean"} <= set(det.columns)
    assert len(pd.read_csv(out / "autofocus_scenes.csv")) == 8
    assert (out / "panel_1d-uniform-pi.png").stat().st_size > 0
    assert json.loads((out / "config.json").read_text())["options"]["scenes"] == 2
    conv = table[(table.method == "conventional") & (table.error == "1d-uniform-pi")]
    sparse = table[(table.method == "sparse-autofocus") & (table.error == "1d-uniform-pi")]
    assert float(sparse["corr_mean"].iloc[0]) > float(conv["corr_mean"].iloc[0])


def test_keep_restarts_only_for_2d(tmp_path):
    out = tmp_path / "pr"
    args = [
        "autofocus",
        "--out",
        str(out),
        "--scenes",
        "1",
        "--size",
        "16",
        "--no-gotcha",
        "--errors",
        "1d-uniform-pi,2d-pi",
        "--methods",
        "conventional,sparse-keep-restarts",
        "--no-progress",
    ]
    assert main(args) == 0
    table = pd.read_csv(out / "autofocus.csv")
    methods = set(zip(table.error, table.method, strict=True))
    assert ("2d-pi", "sparse-keep-restarts") in methods
    assert ("1d-uniform-pi", "sparse-keep-restarts") not in methods


def test_autofocus_command_rejects_unknown_method(tmp_path, capsys):
    try:
        main(["autofocus", "--out", str(tmp_path / "x"), "--methods", "magic"])
    except SystemExit as exc:
        assert "unknown methods" in str(exc)
    else:  # pragma: no cover
        raise AssertionError("expected SystemExit")
    assert not (tmp_path / "x").exists()
