"""``torchsar-eval pfa``: the calibration table on tiny clutter, intervals, argument errors."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch

from torchsar_eval.cli import main
from torchsar_eval.experiments.pfa.calibration import (
    CLUTTER,
    PFA_COLUMNS,
    ClutterCase,
    binomial_interval,
    measure,
)
from torchsar_eval.registry import BUILTIN


def test_binomial_interval_covers_and_matches_beta():
    lo, hi = binomial_interval(0, 1000)
    assert lo == 0.0 and hi == pytest.approx(1 - 0.025 ** (1 / 1000), rel=1e-9)
    lo, hi = binomial_interval(50, 1000)
    assert lo < 0.05 < hi


def test_measure_rows_and_looks_passed():
    x = torch.empty(1, 1, 64, 64).exponential_(generator=torch.Generator().manual_seed(0))
    case = ClutterCase("gamma L=4", "gamma", looks=4.0)
    table = measure([BUILTIN["ca"], BUILTIN["so"]], case, x, [1e-2, 1e-3])
    assert list(table.columns) == PFA_COLUMNS and len(table) == 4
    ca = BUILTIN["ca"].with_options({"pfa": 1e-2, "looks": 4.0})(x)
    row = table[(table.detector == "ca") & (table.design_pfa == 1e-2)].iloc[0]
    assert row.false_alarms == int(ca.mask.sum()) and row.pixels == 64 * 64
    assert np.isclose(row.measured_pfa, row.false_alarms / row.pixels)


def test_cli_pfa_end_to_end(tmp_path):
    try:
        from torchsar.simulate import clutter  # noqa: F401
    except ImportError:
        pytest.skip("torchsar.simulate.clutter is not available yet")
    out = tmp_path / "pfa"
    code = main(
        [
            "pfa",
            "--detectors",
            "ca,os",
            "--size",
            "48",
            "--images",
            "1",
            "--pfa",
            "0.01",
            "--out",
            str(out),
            "--no-progress",
        ]
    )
    assert code == 0
    table = pd.read_csv(out / "pfa.csv")
    assert len(table) == 2 * len(CLUTTER)
    assert set(table.clutter) == {c.name for c in CLUTTER}
    assert (out / "pfa.png").stat().st_size > 0 and (out / "config.json").exists()


@pytest.mark.parametrize(
    ("argv", "msg"),
    [
        (["pfa", "--pfa", "2"], "--pfa"),
        (["pfa", "--detectors", "nope"], "unknown detector"),
        (["pfa", "--size", "4"], "--size"),
    ],
)
def test_cli_pfa_errors(tmp_path, capsys, argv, msg):
    assert main([*argv, "--out", str(tmp_path / "x"), "--no-progress"]) == 2
    assert msg in capsys.readouterr().err


def test_every_registered_detector_runs_with_its_defaults():
    x = torch.empty(2, 1, 40, 40).exponential_(generator=torch.Generator().manual_seed(1))
    for name, spec in BUILTIN.items():
        d = spec(x)
        assert d.mask.shape == x.shape, name
        assert torch.equal(d.mask, d.statistic > d.threshold), name
