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
ARGS = ["run", "--dataset", "sim-chips", "--n", "12", "--detectors", "ca,so", "--shard-size",
        "2", "--batch-size", "2", "--bootstrap", "10", "--export-coco", "--no-progress"]  # fmt: skip
COCO = ["coco/sim-chips__gt.json", "coco/sim-chips__ca.json", "coco/sim-chips__so.json"]


def _saved(parent: Path, name: str) -> int:
    return sum(len(list(p.glob("shards/sim-chips/test/shard-*.state")))
               for p in parent.glob(f".{name}.torchsar-partial-*"))  # fmt: skip


def _interrupt_after(out: Path, shards: int, sig: int) -> int:
    cmd = [sys.executable, "-m", "torchsar_eval.cli", *ARGS, "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while _saved(out.parent, out.name) < shards and proc.poll() is None:
        assert time.monotonic() < deadline, "the run saved no shard in time"
        time.sleep(0.05)
    os.kill(proc.pid, sig)
    proc.wait(timeout=60)
    return proc.returncode, proc.stderr.read().decode()


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT])
def test_interrupted_then_resumed_equals_uninterrupted(tmp_path, sig):
    whole = tmp_path / "whole"
    assert main([*ARGS, "--out", str(whole)]) == 0
    out = tmp_path / "run"
    code, err = _interrupt_after(out, 2, sig)
    if code == 0:
        pytest.skip("the run finished before the signal landed")
    assert not out.exists()
    if sig == signal.SIGINT:
        assert code == 130 and err.strip().endswith("continue with the same command plus --resume")
        assert len(err.strip().splitlines()) == 1
    assert main([*ARGS, "--out", str(out), "--resume"]) == 0
    for name in TABLES + COCO:
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name
    assert not list(tmp_path.glob(".run.torchsar-*"))  # the staging folder was adopted


def test_resume_with_other_options_is_refused(tmp_path):
    out = tmp_path / "run"
    code, _ = _interrupt_after(out, 1, signal.SIGKILL)
    if code == 0:
        pytest.skip("the run finished before the signal landed")
    other = [a if a != "ca,so" else "ca" for a in ARGS]
    assert main([*other, "--out", str(out), "--resume"]) == 2
    assert not out.exists()
