"""Detectors that live outside torchsar: by import path on the command line (one process,
two workers, Ray), by name through an entry point, and refused in one line when a worker
could not import them (defined in ``__main__``)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pandas as pd
import pytest

import torchsar_eval as te
from torchsar_eval.cli import main
from torchsar_eval.detector import Detector, check_portable
from torchsar_eval.errors import EvalError

EXTERNAL = Path(__file__).parent / "external"
TABLES = ["summary.csv", "roc.csv", "pr.csv", "breakdown.csv", "per_image.csv", "roc_pixel.csv"]
ARGS = [
    "run",
    "--dataset",
    "sim-chips",
    "--n",
    "6",
    "--batch-size",
    "2",
    "--shard-size",
    "2",
    "--detectors",
    "ca,ratio=mydets:RatioNet,mydets:bright_boxes",
    "--param",
    "ratio.window=7",
    "--param",
    "bright_boxes.threshold=0.5",
    "--bootstrap",
    "20",
    "--no-progress",
]


def _cli(args: list[str], extra_path: Path = EXTERNAL, cwd: Path | None = None):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(extra_path), *sys.path])}
    return subprocess.run(
        [sys.executable, "-m", "torchsar_eval.cli", *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        cwd=cwd,
    )


def _tables(out: Path) -> dict[str, bytes]:
    return {name: (out / name).read_bytes() for name in TABLES}


@pytest.fixture(scope="module")
def one_process(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ext") / "w1"
    done = _cli([*ARGS, "--out", str(out)])
    assert done.returncode == 0, done.stderr
    return out


@pytest.mark.integration
def test_external_detectors_are_scored_beside_a_builtin(one_process):
    summary = pd.read_csv(one_process / "summary.csv").set_index("detector")
    assert list(summary.index) == ["ca", "ratio", "bright_boxes"]
    assert (summary.images == 6).all() and (summary.targets == 6).all()
    # the box detector declared no masks: no pixel metrics, a probability threshold of 0.5
    assert pd.isna(summary.loc["bright_boxes", "pd_pixel"])
    assert summary.loc["bright_boxes", "score_threshold"] == 0.5
    assert summary.loc["ratio", "pd_pixel"] > 0 and summary.loc["bright_boxes", "tp"] > 0
    cfg = (one_process / "config.json").read_text()
    assert '"window": 7' in cfg and '"_ref": "mydets:RatioNet"' in cfg


@pytest.mark.integration
def test_two_workers_equal_one_process(one_process, tmp_path):
    out = tmp_path / "w2"
    done = _cli([*ARGS, "--workers", "2", "--out", str(out)])
    assert done.returncode == 0, done.stderr
    assert _tables(out) == _tables(one_process)


@pytest.mark.integration
def test_ray_equals_one_process(one_process, tmp_path):
    pytest.importorskip("ray")
    out = tmp_path / "ray"
    done = _cli([*ARGS, "--engine", "ray", "--out", str(out)])
    assert done.returncode == 0, done.stderr
    assert _tables(out) == _tables(one_process)


def test_an_entry_point_detector_is_found_by_name(tmp_path, monkeypatch, capsys):
    dist = tmp_path / "site" / "mydets_plugin-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: mydets-plugin\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[torchsar.detectors]\nratio-net = mydets:RatioNet\n")
    monkeypatch.syspath_prepend(str(EXTERNAL))
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    out = tmp_path / "ep"
    assert (
        main(
            [
                "run",
                "--dataset",
                "sim-chips",
                "--n",
                "2",
                "--detectors",
                "ratio-net",
                "--no-progress",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert pd.read_csv(out / "summary.csv").detector.tolist() == ["ratio-net"]
    capsys.readouterr()
    assert main(["run", "--help"]) == 0
    assert "ratio-net" in capsys.readouterr().out


@pytest.mark.integration
def test_a_main_only_detector_with_two_workers_gets_one_line(tmp_path):
    script = tmp_path / "script.py"
    script.write_text(
        textwrap.dedent(f"""
        import sys
        import torchsar as ts
        from torchsar_eval.cli import main

        def mine(x):
            return ts.cfar.ca(x)

        sys.exit(main(["run", "--dataset", "sim-chips", "--n", "4", "--detectors",
                       "__main__:mine", "--workers", "2", "--shard-size", "2",
                       "--no-progress", "--out", {str(tmp_path / "out")!r}]))
    """)
    )
    done = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=300
    )
    lines = [ln for ln in done.stderr.splitlines() if ln.strip()]
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert "defined in __main__" in lines[0] and "--workers 1" in lines[0]
    assert not (tmp_path / "out").exists()


def _from_main(x):
    raise AssertionError("never called")


def test_python_api_refuses_main_objects_and_lambdas_for_workers():
    _from_main.__module__ = "__main__"  # as if defined in a script
    with pytest.raises(EvalError, match=r"defined in __main__ .* workers=1"):
        check_portable([Detector("m", _from_main)])
    with pytest.raises(EvalError, match="cannot be sent to worker processes"):
        check_portable([Detector("l", lambda x: x)])
    with pytest.raises(EvalError, match="workers=1"):
        te.evaluate(
            "sim-chips", {"l": lambda x: x}, n=2, execution=te.Execution(workers=2, progress=False)
        )


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--detectors", "nosuch"], "unknown detector 'nosuch'"),
        (["--detectors", "nosuchmodule:fn"], "cannot import detector 'nosuchmodule:fn'"),
        (["--detectors", "mydets:nothing"], "has no attribute 'nothing'"),
        (["--detectors", "mydets:RatioNet", "--param", "RatioNet.bogus=1"], "rejects its options"),
        (
            ["--detectors", "mydets:bright_boxes", "--param", "bright_boxes.bogus=1"],
            "detector bright_boxes has no option 'bogus'; valid: k",
        ),
    ],
)
def test_bad_references_are_one_line(tmp_path, monkeypatch, capsys, extra, message):
    monkeypatch.syspath_prepend(str(EXTERNAL))
    code = main(
        [
            "run",
            "--dataset",
            "sim-chips",
            "--n",
            "2",
            "--no-progress",
            "--out",
            str(tmp_path / "x"),
            *extra,
        ]
    )
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1, lines
    assert message in lines[0]
    assert not (tmp_path / "x").exists()
