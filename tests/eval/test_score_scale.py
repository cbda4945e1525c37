"""Each detector's scores on one scale everywhere: a statistic with one design threshold
keeps its own values (probabilities stay probabilities) with that threshold beside them in
every table, the export and the gallery; the ratio scale on request; every metric the same
on both (a strictly increasing map of the scores changes no number)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import torch

import torchsar_eval as te
from torchsar.cfar import detection_from
from torchsar_eval.cli import main
from torchsar_eval.errors import EvalError

N = 8
NUMERIC_SAME = ["tp", "false_alarms", "fn", "pd", "precision", "f1", "ap50", "ap50_95"]


class Probability(torch.nn.Module):
    """Contrast to the image mean through a sigmoid: a probability map, threshold 0.5."""

    def forward(self, x: torch.Tensor):
        ratio = x / x.mean(dim=(2, 3), keepdim=True)
        return detection_from(torch.sigmoid(ratio.double() - 6.0), 0.5)


def _run(tmp_path, name: str, scale: str):
    det = te.Detector("prob", Probability(), scale=scale)
    return te.evaluate(
        "sim-chips",
        {"prob": det},
        n=N,
        out=tmp_path / name,
        export_coco=True,
        scoring=te.Scoring(replicates=20, rules=te.ObjectRules(floor=0.5)),
        progress=False,
    )


@pytest.mark.figures
def test_probabilities_stay_probabilities_and_no_number_moves(tmp_path):
    own, ratio = _run(tmp_path, "own", "auto"), _run(tmp_path, "ratio", "ratio")
    a, b = own.summary.iloc[0], ratio.summary.iloc[0]
    assert a["score_threshold"] == 0.5 and b["score_threshold"] == 1.0
    assert a["tp"] > 0 and a["false_alarms"] > 0
    cols = [c for c in own.summary.columns if c not in ("score_threshold",)]
    pd.testing.assert_series_equal(own.summary[cols].iloc[0], ratio.summary[cols].iloc[0])
    for table in ("roc.csv", "pr.csv"):
        x = pd.read_csv(tmp_path / "own" / table)
        y = pd.read_csv(tmp_path / "ratio" / table)
        thr = [c for c in x.columns if "threshold" in c or c == "score"]
        assert thr, table
        for c in thr:
            got = x[c].to_numpy(float)
            fin = np.isfinite(got)
            assert ((got[fin] > 0) & (got[fin] <= 1)).all(), (table, c)
            # the same levels: ratio = probability / 0.5
            np.testing.assert_allclose(got[fin], y[c].to_numpy(float)[fin] * 0.5, rtol=1e-12)
        rest = [c for c in x.columns if c not in thr]
        pd.testing.assert_frame_equal(x[rest], y[rest])
    exported = json.loads(next((tmp_path / "own" / "coco").glob("*__prob.json")).read_text())
    scores = np.array([d["score"] for d in exported])
    assert scores.size and (scores > 0.25).all() and (scores <= 1).all()
    cases = pd.read_csv(tmp_path / "own" / "gallery" / "cases.csv")
    assert cases["score"].dropna().between(0, 1).all()


class Drifting(torch.nn.Module):
    """A statistic whose single threshold is recomputed from each batch."""

    def forward(self, x: torch.Tensor):
        return detection_from(x, float(x.mean()) * 20)


def test_a_threshold_that_changes_between_batches_is_named(tmp_path):
    ex = te.Execution(batch_size=1, shard_size=64)
    with pytest.raises(EvalError, match=r"threshold changed .*--param drift\.scale=ratio"):
        te.evaluate("sim-chips", {"drift": Drifting()}, n=4, execution=ex, progress=False)
    det = te.Detector("drift", Drifting(), scale="ratio")
    res = te.evaluate("sim-chips", {"drift": det}, n=4, execution=ex, progress=False)
    assert res.summary["score_threshold"].iloc[0] == 1.0


def test_scale_is_a_param_of_every_detector(tmp_path):
    out = tmp_path / "run"
    assert (
        main(
            [
                "run",
                "--dataset",
                "sim-chips",
                "--n",
                "4",
                "--detectors",
                "ca,os",
                "--param",
                "ca.scale=ratio",
                "--no-progress",
                "--bootstrap",
                "0",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    s = pd.read_csv(out / "summary.csv").set_index("detector")
    assert s.loc["ca", "score_threshold"] == 1.0 and s.loc["os", "score_threshold"] > 1.0
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["options"]["detectors"]["ca"]["_scale"] == "ratio"
    with pytest.raises(EvalError, match="scale must be one of"):
        te.Detector("x", Probability(), scale="probability")
