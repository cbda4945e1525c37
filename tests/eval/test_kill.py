"""Kill test: SIGKILL or SIGTERM at a random point of a real run leaves ``--out`` empty, or
holding a complete run (the old one or the new one), once the next start has settled what
a killed run left behind."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from contextlib import nullcontext
from pathlib import Path

import pytest

from torchsar_eval.cli import main
from torchsar_eval.output import RUN_MARKER, StaleRunWarning, has_saved_work, write_marker

RUN_FILES = {"summary.csv", "roc.csv", "roc_pixel.csv", "summary.md", "config.json"}
OLD_RUN = {"config.json": "old", "stale.csv": "old"}


def _start(out, old: bool) -> subprocess.Popen:
    if old:
        out.mkdir()
        for name, text in OLD_RUN.items():
            (out / name).write_text(text)
        write_marker(out)
    argv = ["run", "--dataset", "sim-chips", "--n", "4", "--detectors", "ca", "--no-progress"]
    argv += ["--out", str(out)] + (["--overwrite"] if old else [])
    cmd = [sys.executable, "-m", "torchsar_eval.cli", *argv]
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _hidden(parent):
    return [p for p in parent.iterdir() if ".torchsar-" in p.name]


def _kill_when_writing(proc: subprocess.Popen, parent, sig: int, delay: float) -> None:
    """Send ``sig`` ``delay`` seconds after the run's first hidden folder appears."""
    deadline = time.monotonic() + 60
    while not _hidden(parent) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    time.sleep(delay)
    proc.send_signal(sig)


def _state(out) -> str:
    if not out.exists():
        return "none"
    names = {p.name for p in out.iterdir()} - {RUN_MARKER}
    if names == set(OLD_RUN):
        return "old"
    assert names >= RUN_FILES and any(n.startswith("roc_") and n.endswith(".png") for n in names)
    assert "stale.csv" not in names
    return "new"


def _kill_cases(tmp_path, cases, seed: int) -> None:
    """Start one run per case at once (``--overwrite`` of an old run or into a new folder),
    kill each at a random point while it writes, then check what is left."""
    rng = random.Random(seed)
    parents = [tmp_path / f"case{i}" for i in range(len(cases))]
    procs = []
    for parent, (_sig, old) in zip(parents, cases, strict=True):
        parent.mkdir()
        procs.append(_start(parent / "out", old))
    for proc, parent, (sig, _old) in zip(procs, parents, cases, strict=True):
        _kill_when_writing(proc, parent, sig, rng.uniform(0.0, 1.5))
    for proc, parent, (sig, old) in zip(procs, parents, cases, strict=True):
        code = proc.wait(timeout=60)
        if sig == signal.SIGTERM:  # the run stops itself and says so in one line
            err = proc.stderr.read().strip()
            assert code in (0, 143, -signal.SIGTERM), err  # -15: after main() returned
            hint = "torchsar-eval: terminated; continue with the same command plus --resume"
            assert err == (hint if code == 143 else ""), err
            # only its staging folder may stay (kept for --resume); the next start settles it
            assert all(".torchsar-partial-" in h.name for h in _hidden(parent))
        saved = [p for p in _hidden(parent) if p.is_dir() and has_saved_work(p)]
        with pytest.warns(StaleRunWarning) if saved else nullcontext():
            assert main(["run", "--n", "0", "--out", str(parent / "next")]) == 2  # next start
        # what is left is only a killed run's saved work, kept for --resume, until cleaned
        left = _hidden(parent)
        assert left == saved
        assert main(["clean", str(parent / "out")]) == 0
        assert _hidden(parent) == []
        assert _state(parent / "out") in (("old", "new") if old else ("none", "new"))


needs_signals = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")


@pytest.mark.figures  # a complete folder holds its figures
@pytest.mark.integration
@needs_signals
def test_kill_at_random_points_leaves_no_folder_or_a_complete_one(tmp_path):
    # SIGKILL while replacing an old run (the hardest case: an old run aside, a staging
    # folder, nothing cleaned by the run itself); SIGTERM while writing a new one. Every
    # step of the publishing protocol is killed deterministically in test_output.py.
    _kill_cases(tmp_path, [(signal.SIGKILL, True), (signal.SIGTERM, False)], seed=14)


@pytest.mark.integration
def test_a_finished_two_worker_run_is_quiet(tmp_path):
    """A run that ends normally lets its worker processes exit by themselves: nothing on
    stderr (no semaphores of killed workers left for the resource tracker)."""
    argv = [
        "run",
        "--dataset",
        "sim-chips",
        "--n",
        "4",
        "--detectors",
        "ca",
        "--no-progress",
        "--workers",
        "2",
        "--shard-size",
        "2",
        "--out",
        str(tmp_path / "run"),
    ]
    done = subprocess.run(
        [sys.executable, "-m", "torchsar_eval.cli", *argv],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0 and done.stderr == "", done.stderr


def _stat(pid: int | str) -> list[str] | None:
    """``/proc/PID/stat`` after the command name (state, parent, ...), ``None`` if gone."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None


def _children(pid: int) -> list[int]:
    """Live processes whose parent is ``pid``."""
    stats = {int(e): _stat(e) for e in os.listdir("/proc") if e.isdigit()}
    return [p for p, f in stats.items() if f and int(f[1]) == pid and f[0] != "Z"]


def _alive(pid: int) -> bool:
    fields = _stat(pid)
    return fields is not None and fields[0] != "Z"


@pytest.mark.integration
@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads /proc")
def test_workers_die_with_their_driver(tmp_path):
    """SIGKILL to the driver of a two-worker run: no worker is alive 5 s later (before,
    they stayed blocked on a pipe for minutes)."""
    argv = [
        "run",
        "--dataset",
        "sim-chips",
        "--n",
        "400",
        "--detectors",
        "os,region",
        "--shard-size",
        "4",
        "--workers",
        "2",
        "--no-progress",
        "--out",
        str(tmp_path / "o"),
    ]
    proc = subprocess.Popen(
        [sys.executable, "-m", "torchsar_eval.cli", *argv],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 120
    workers: list[int] = []
    while time.monotonic() < deadline and proc.poll() is None:
        kids = _children(proc.pid)
        if len(kids) >= 2:  # (the resource tracker and the workers)
            time.sleep(1.0)  # the workers past their start
            workers = _children(proc.pid)
            break
        time.sleep(0.05)
    assert workers, "no worker started"
    proc.kill()
    proc.wait(timeout=30)
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and any(_alive(p) for p in workers):
        time.sleep(0.1)
    assert not [p for p in workers if _alive(p)]
