"""Kill a run mid-way (SIGKILL or Ctrl-C), resume it: the tables equal an uninterrupted run's."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from torchsar_eval.cli import main

TABLES = ["summary.csv", "roc.csv", "pr.csv", "roc_pixel.csv", "breakdown.csv", "per_image.csv"]
ARGS = [
    "run",
    "--dataset",
    "sim-chips",
    "--n",
    "40",  # 20 shards: after the second is saved, the run lasts about two seconds more
    "--detectors",
    "ca,so",
    "--shard-size",
    "2",
    "--batch-size",
    "2",
    "--bootstrap",
    "10",
    "--export-coco",
    "--no-progress",
]
COCO = ["coco/sim-chips__gt.json", "coco/sim-chips__ca.json", "coco/sim-chips__so.json"]


def _saved(parent: Path, name: str) -> int:
    return sum(
        len(list(p.glob("shards/sim-chips/test/shard-*.state")))
        for p in parent.glob(f".{name}.torchsar-partial-*")
    )


def _interrupted(tmp_path: Path, shards: int, sig: int) -> tuple[Path, int, str]:
    """A run killed by ``sig`` once it has saved ``shards`` shards: its ``--out`` path, exit
    code and standard error. A run that ends before the signal lands (on a loaded machine
    the poll can sleep through the two seconds it has) is started again in a new folder, up
    to three times, and only then the test is skipped."""
    for attempt in range(3):
        out = tmp_path / f"attempt-{attempt}" / "run"
        out.parent.mkdir()
        code, err = _interrupt_after(out, shards, sig)
        if code != 0:
            return out, code, err
    pytest.skip("three runs ended before the signal landed")


def _interrupt_after(out: Path, shards: int, sig: int) -> tuple[int, str]:
    cmd = [sys.executable, "-m", "torchsar_eval.cli", *ARGS, "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while _saved(out.parent, out.name) < shards and proc.poll() is None:
        assert time.monotonic() < deadline, "the run saved no shard in time"
        time.sleep(0.01)
    os.kill(proc.pid, sig)
    proc.wait(timeout=60)
    return proc.returncode, proc.stderr.read().decode()


@pytest.mark.parametrize(
    "sig", [pytest.param(s, marks=pytest.mark.integration) for s in (signal.SIGKILL, signal.SIGINT)]
)
def test_interrupted_then_resumed_equals_uninterrupted(tmp_path, sig):
    whole = tmp_path / "whole"
    assert main([*ARGS, "--out", str(whole)]) == 0
    out, code, err = _interrupted(tmp_path, 2, sig)
    assert not out.exists()
    if sig == signal.SIGINT:
        assert code == 130 and err.strip().endswith("continue with the same command plus --resume")
        assert len(err.strip().splitlines()) == 1
    assert main([*ARGS, "--out", str(out), "--resume"]) == 0
    for name in TABLES + COCO:
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name
    assert not list(out.parent.glob(".run.torchsar-*"))  # the staging folder was adopted


@pytest.mark.integration
def test_resume_with_other_options_is_refused(tmp_path):
    out, _, _ = _interrupted(tmp_path, 1, signal.SIGKILL)
    other = [a if a != "ca,so" else "ca" for a in ARGS]
    assert main([*other, "--out", str(out), "--resume"]) == 2
    assert not out.exists()


def test_resume_refuses_a_dataset_that_changed(tmp_path):
    """Files added, resized or touched between the interrupted run and --resume: refused,
    saying what changed (the saved shards would no longer describe the data)."""
    import numpy as np
    from skimage import io

    from torchsar_eval.api import _Plan
    from torchsar_eval.datasets import make_dataset
    from torchsar_eval.errors import EvalError
    from torchsar_eval.registry import BUILTIN
    from torchsar_eval.result import Scoring
    from torchsar_eval.resume import check_resumable, fingerprint
    from torchsar_eval.settings import Execution

    data = tmp_path / "data"
    data.mkdir()

    def chip(stem, value=20):
        io.imsave(data / f"{stem}.png", np.full((32, 32), value, np.uint8), check_contrast=False)
        io.imsave(data / f"{stem}.mask.png", np.zeros((32, 32), np.uint8), check_contrast=False)

    chip("a")
    chip("b")
    plan = _Plan([BUILTIN["ca"]], Scoring(), Execution(), None, None, None, "px", False, 0)
    record = tmp_path / "resume.json"

    def check():
        ds = make_dataset(f"folder:{data}?type=intensity")
        check_resumable(record, fingerprint(plan, {"d": ds}))

    check()  # the interrupted run records its fingerprint
    check()  # nothing changed: resumable
    chip("c")
    with pytest.raises(EvalError, match=r"dataset d changed .*4 files of \d+ bytes then, 6 files"):
        check()
    (data / "c.png").unlink()
    (data / "c.mask.png").unlink()
    os.utime(data / "a.png", ns=(1, 1))
    with pytest.raises(EvalError, match="dataset d changed .*files modified"):
        check()


def test_resume_refuses_predictions_that_changed(tmp_path):
    """A predictions file replaced between the interrupted run and --resume (same name, even
    the same size and time): refused, naming it (before, the run mixed old and new shards)."""
    import json

    from torchsar_eval.api import _Plan
    from torchsar_eval.errors import EvalError
    from torchsar_eval.result import Scoring
    from torchsar_eval.resume import check_resumable, fingerprint
    from torchsar_eval.saved import predictions
    from torchsar_eval.settings import Execution

    path = tmp_path / "results.json"
    rows = [{"image_id": 1, "bbox": [1, 2, 3, 4], "score": 0.5}]
    path.write_text(json.dumps(rows))
    record = tmp_path / "resume.json"

    def check():
        plan = _Plan(
            [predictions(path, name="cnn")],
            Scoring(),
            Execution(),
            None,
            None,
            None,
            "px",
            False,
            0,
        )
        check_resumable(record, fingerprint(plan, {}))

    check()
    check()
    stat = path.stat()
    path.write_text(json.dumps([{**rows[0], "score": 0.7}]))  # same size
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns))  # and the same time
    with pytest.raises(EvalError, match=r"predictions of cnn .*results.json.* not those"):
        check()


@pytest.mark.parametrize("suffix", [".json", ".csv"])
def test_a_fifo_as_predictions_is_refused_at_once(tmp_path, suffix):
    from torchsar_eval.errors import EvalError
    from torchsar_eval.saved import predictions

    fifo = tmp_path / f"results{suffix}"
    os.mkfifo(fifo)
    with pytest.raises(EvalError, match="not a regular file"):
        predictions(fifo)
