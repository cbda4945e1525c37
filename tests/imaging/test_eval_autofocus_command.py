from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from torchsar_eval.cli import main


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


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("torchsar-eval: error: ")
    return err[0]


def test_autofocus_command_rejects_unknown_method(tmp_path, capsys):
    assert main(["autofocus", "--out", str(tmp_path / "x"), "--methods", "magic"]) == 2
    assert "unknown methods" in _one_line_error(capsys)
    assert not (tmp_path / "x").exists()


def _gotcha_folder(tmp_path, kind: str):
    folder = tmp_path / kind
    folder.mkdir()
    name = folder / "data_3dsar_pass1_az001_HH.mat"
    if kind == "garbage":
        name.write_bytes(b"this is not a MATLAB file at all" * 10)
    elif kind == "truncated":
        from scipy.io import savemat

        data = {"fp": np.ones((8, 4), complex), "freq": np.linspace(9e9, 9.1e9, 8)}
        savemat(name, {"data": data})
        name.write_bytes(name.read_bytes()[:100])
    return folder


@pytest.mark.parametrize(
    "kind,message",
    [
        ("missing", "does not exist"),
        ("empty", "no GOTCHA files"),
        ("garbage", "cannot read GOTCHA file"),
        ("truncated", "cannot read GOTCHA file"),
    ],
)
def test_bad_gotcha_folder_exits_2_before_any_work(tmp_path, capsys, kind, message):
    folder = tmp_path / "nowhere" if kind == "missing" else _gotcha_folder(tmp_path, kind)
    out = tmp_path / "out"
    assert main(["autofocus", "--gotcha", str(folder), "--out", str(out), "--no-progress"]) == 2
    assert message in _one_line_error(capsys)
    assert not out.exists()
