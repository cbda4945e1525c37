"""``--param KEY=VALUE`` and ``--param '*.KEY=VALUE'``: one option for every detector that has
it, a detector's own setting winning."""

from __future__ import annotations

import json

import pytest

from torchsar_eval.cli import main
from torchsar_eval.commands.run.options import check_run_args
from torchsar_eval.errors import EvalError
from torchsar_eval.options import parse_params


def _args(*params, detectors="ca,os,region", predictions=()):
    from torchsar_eval.cli import build_parser  # the real parser's defaults

    parser = build_parser()
    argv = ["run", "--detectors", detectors, *[f"--param={p}" for p in params]]
    argv += [f"--predictions={p}" for p in predictions]
    return parser.parse_args(argv)


def test_parse_accepts_every_detector_forms():
    assert parse_params(["pfa=1e-6", "*.guard=3", "ca.train=9"]) == {
        "*": {"pfa": 1e-6, "guard": 3},
        "ca": {"train": 9},
    }
    with pytest.raises(EvalError, match="DETECTOR.NAME=VALUE"):
        parse_params(["a.b.c=1"])


@pytest.mark.parametrize("form", ["pfa=1e-5", "*.pfa=1e-5"])
def test_an_option_reaches_every_detector_that_has_it(form):
    dets = {d.name: d for d in check_run_args(_args(form, "ca.pfa=1e-3")).detectors}
    assert dets["ca"].options["pfa"] == 1e-3  # its own wins
    assert dets["os"].options["pfa"] == 1e-5
    assert "pfa" not in dets["region"].options or dets["region"].options.get("pfa") == 1e-5


def test_an_option_no_detector_has_is_refused():
    with pytest.raises(EvalError, match="no detector of this run has the option 'gaurd'"):
        check_run_args(_args("gaurd=3"))


def test_saved_predictions_take_the_harness_options_only(tmp_path):
    path = tmp_path / "p.json"
    path.write_text(json.dumps([]))
    dets = {
        d.name: d
        for d in check_run_args(
            _args("guard=3", "threshold=0.5", detectors="ca", predictions=[f"cnn={path}"])
        ).detectors
    }
    assert dets["ca"].options["guard"] == 3 and dets["ca"].threshold == 0.5
    assert dets["cnn"].threshold == 0.5


def test_the_cli_records_the_options_applied(tmp_path):
    out = tmp_path / "run"
    main(
        [
            "run",
            "--dataset",
            "sim-chips",
            "--n",
            "2",
            "--detectors",
            "ca,so",
            "--param",
            "train=6",
            "--param",
            "so.train=5",
            "--bootstrap",
            "0",
            "--out",
            str(out),
        ]
    )
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["options"]["detectors"]["ca"]["train"] == 6
    assert cfg["options"]["detectors"]["so"]["train"] == 5
