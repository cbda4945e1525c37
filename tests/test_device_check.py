"""The prepared GPU run (``scripts/device_check.sh``) and its whole-scene benchmark
(``scripts/scene_device.py``), dry-run on the CPU so that a session lent a GPU finds them
working: every step exits 0 and the results fit what the device tool brings back."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

from tests.scripts import SCRIPTS, load_script


def test_the_scene_benchmark_runs_every_detector(capsys):
    assert (
        load_script("scene_device").main(
            ["--size", "300", "--device", "cpu", "--tile", "128", "--detectors", "ca", "os"]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert re.search(r"scene 300\^2 .* copy [\d.]+ s", out)
    for name in ("ca", "os"):
        assert re.search(rf"{name}: [\d.]+ s, [\d,]+ Mpx/s .* [1-9]\d* detections", out), out


@pytest.mark.integration
def test_the_device_check_dry_run_passes_every_step(tmp_path):
    env = {
        **os.environ,
        "OUT": str(tmp_path / "out"),
        "PYTHON": sys.executable,
        "DEVICE": "cpu",
        "N": "2",
        "SCENE": "512",
        "THROUGHPUT_N": "16",
        "CPU_WORKERS": "1",
        "DEVICE_WORKERS": "1",
        "TMPDIR": str(tmp_path),
    }
    run = subprocess.run(
        ["bash", str(SCRIPTS / "device_check.sh")],
        cwd=SCRIPTS.parent,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    out = tmp_path / "out"
    status = (out / "status.txt").read_text().splitlines()
    assert len(status) == 7 and all(": exit 0 " in line for line in status), status
    files = sorted(p.name for p in out.iterdir())
    assert files == [
        "gpu_cfars.csv",
        "log.txt",
        "status.txt",
        "throughput_cpu.csv",
        "throughput_device.csv",
    ]  # at most 8 files come back from a device run
