"""The ``run`` command's bad inputs and unsafe states, one table: each case exits 2 with one
line naming the option (or, for a warning, finishes and says it on one line), before any
memory or work is spent on it."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from torchsar_eval.cli import main

BASE = ["run", "--dataset", "sim-chips", "--detectors", "ca", "--no-progress"]


def _saved_work(tmp_path):
    """A killed run's staging folder for ``out`` with a saved shard (no process holds it)."""
    left = tmp_path / ".out.torchsar-partial-999999-0123abcd@elsewhere"
    (left / "shards").mkdir(parents=True)
    (left / "resume.json").write_text("{}")
    (left / "shards" / "shard-000000.state").write_bytes(b"x")
    return left


def _running(tmp_path):
    """A staging folder for ``out`` whose lock a live process holds."""
    left = _saved_work(tmp_path)
    code = (
        "import sys; from torchsar_eval.locks import hold\n"
        f"with hold({str(left) + '.lock'!r}):\n    print('held', flush=True); sys.stdin.read()"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout.readline().strip() == "held"
    return proc


CASES = {
    "n beyond any dataset": (
        ["--n", "100000000000000"],
        None,
        r"--n 100000000000000: must be an integer from 1 to 10,000,000",
    ),
    "n not an integer": (["--n", "1e14"], None, r"argument --n: invalid int value: '1e14'"),
    "a 100k-character --param": (
        ["--param", "ca.train=" + "9" * 100_000],
        None,
        r"--param ca.train=9+\.\.\.: 100009 characters",
    ),
    "a deeply nested --param": (
        ["--param", "ca.train=" + "[" * 900],
        None,
        r"detector ca rejects its options",
    ),
    "resume and discard": (["--resume", "--discard"], None, r"--resume and --discard exclude"),
    "max-bad beyond 1": (
        ["--skip-bad", "--max-bad", "2"],
        None,
        r"--max-bad 2\.0: must be a share from 0 to 1",
    ),
    "a device without data": (["--device", "meta"], None, r"--device 'meta' holds no data"),
    "a closing of 300 px": (["--closing", "300"], None, r"closing must be at most 64 px"),
    "rank-by not a metric": (
        ["--rank-by", "speed"],
        None,
        r"--rank-by 'speed': not a metric; choose one of f1, precision",
    ),
    "saved work, no --resume": (
        [],
        _saved_work,
        r"an interrupted run left its saved work in .*1 saved shard.*"
        r"continue it with --resume, or start over with --discard",
    ),
    "another run writes --out": ([], _running, r"being written by another run \(process 999999"),
    "another run writes --out, resume": (["--resume"], _running, r"being written by another"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_input_is_one_line_exit_2(case, tmp_path, capsys):
    extra, prepare, message = CASES[case]
    holder = prepare(tmp_path) if prepare else None
    try:
        size = [] if "--n" in extra else ["--n", "2"]
        code = main([*BASE, *size, "--out", str(tmp_path / "out"), *extra])
    finally:
        if isinstance(holder, subprocess.Popen):
            holder.stdin.close()
            holder.wait(timeout=30)
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1 and len(err) < 1000, err[:2000]
    assert err.startswith("torchsar-eval: error: ")
    assert re.search(message, err), err
    assert not (tmp_path / "out").exists()


def test_more_workers_than_cores_are_capped_with_a_warning(tmp_path, monkeypatch):
    import os

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0}, raising=False)
    with pytest.warns(UserWarning, match=r"64 workers are more than this machine's 1 cores"):
        assert main([*BASE, "--n", "2", "--workers", "64", "--out", str(tmp_path / "out")]) == 0


DETECTORS = """
import sys
from torchsar.cfar import ca


def quits(images):
    sys.exit(0)


class Broken:
    def __init__(self):
        raise RuntimeError("no weights")

    def __call__(self, images):
        return ca(images)


def fine(images):
    return ca(images)
"""


@pytest.mark.parametrize(
    ("spec", "message", "extra"),
    [
        ("{mod}:quits", r"detector \S*quits called sys.exit\(0\)", []),
        pytest.param(
            "{mod}:quits",
            r"detector \S*quits called sys.exit\(0\)",
            ["--workers", "2", "--shard-size", "1"],
            marks=pytest.mark.integration,
        ),  # in worker processes
        ("{mod}:Broken", r"detector '\S+:Broken' could not be built: RuntimeError: no weights", []),
    ],
)
def test_a_detector_that_exits_or_fails_to_build_is_one_line(
    spec, message, extra, tmp_path, capsys, monkeypatch
):
    """A detector calling ``sys.exit(0)`` (before: exit 0, no output) or a class whose
    ``__init__`` raises (before: a traceback) ends the run with exit 2 and one line."""
    mod = f"dets_{abs(hash(str(tmp_path))) % 10**8}"
    (tmp_path / f"{mod}.py").write_text(DETECTORS)
    monkeypatch.chdir(tmp_path)
    code = main(
        [
            *BASE[:3],
            "--n",
            "2",
            "--detectors",
            spec.format(mod=mod),
            "--no-progress",
            "--out",
            str(tmp_path / "out"),
            *extra,
        ]
    )
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1 and re.search(message, err), err
    assert not (tmp_path / "out").exists()


@pytest.mark.figures
def test_names_are_drawn_as_plain_text(tmp_path, monkeypatch):
    """A detector named with matplotlib mathtext (``a$\\x$b``) runs to the end, figures
    and report included (before: a traceback after all the scoring)."""
    mod = f"dets_{abs(hash(str(tmp_path))) % 10**8}"
    (tmp_path / f"{mod}.py").write_text(DETECTORS)
    monkeypatch.chdir(tmp_path)
    name = "a$\\x$b"
    code = main(
        [
            *BASE[:3],
            "--n",
            "2",
            "--detectors",
            f"{name}={mod}:fine",
            "--no-progress",
            "--out",
            str(tmp_path / "out"),
        ]
    )
    assert code == 0
    assert name in (tmp_path / "out" / "summary.csv").read_text()
    assert (tmp_path / "out" / "report.html").is_file()
