"""Lock files: held while the holder lives (another process included), free once it dies."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from torchsar_eval.locks import LockHeldError, hold, is_held

HOLDER = """
import sys, time
from torchsar_eval.locks import hold
with hold(sys.argv[1]):
    print("held", flush=True)
    sys.stdin.read()  # until the parent closes our stdin (or kills us)
    time.sleep(float(sys.argv[2]))
"""


def _holder(lock, linger: float = 0.0) -> subprocess.Popen:
    """A second process that holds ``lock`` until its stdin closes (then ``linger`` s)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(lock), str(linger)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_hold_removes_its_file_and_refuses_a_second_holder(tmp_path):
    lock = tmp_path / "a.lock"
    assert not is_held(lock) and not lock.exists()  # is_held creates nothing
    with hold(lock) as path:
        assert path == lock and lock.exists() and is_held(lock)
        with pytest.raises(LockHeldError, match="a.lock is held by another running process"):
            hold(lock).__enter__()
        with pytest.raises(LockHeldError, match="^busy$"):
            hold(lock, wait=0.1, message="busy").__enter__()
    assert not lock.exists() and not is_held(lock)


def test_a_lock_held_by_another_process_is_free_once_it_is_killed(tmp_path):
    lock = tmp_path / "b.lock"
    proc = _holder(lock)
    try:
        assert is_held(lock)
        with pytest.raises(LockHeldError), hold(lock, wait=0.2):
            pass
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert lock.exists() and not is_held(lock)  # the dead holder's file stays, free
    with hold(lock):
        assert is_held(lock)
    assert not lock.exists()


def test_hold_waits_for_a_holder_that_finishes(tmp_path):
    lock = tmp_path / "c.lock"
    proc = _holder(lock, linger=0.3)
    proc.stdin.close()  # the holder releases about 0.3 s from now
    t0 = time.monotonic()
    with hold(lock, wait=30):
        assert time.monotonic() - t0 < 30
        assert proc.wait(timeout=30) == 0
    assert not lock.exists()
