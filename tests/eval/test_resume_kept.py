"""Saved work survives whatever stops a run: an error in a shard, a dead worker, a full disk
while saving a shard or at the final write, a refused resume, another run started in the same
folder. Each time the staging folder is kept, the error says where, and ``resume`` scores only
the missing shards and publishes the same tables as an uninterrupted run."""

from __future__ import annotations

import errno
import os

import pytest
import torch

import torchsar as ts
from torchsar_eval import evaluate
from torchsar_eval.detector import Detector
from torchsar_eval.errors import EvalError
from torchsar_eval.output import StaleRunWarning, hidden_folders
from torchsar_eval.registry import BUILTIN
from torchsar_eval.settings import Execution

TABLES = ["summary.csv", "roc.csv", "pr.csv", "roc_pixel.csv", "breakdown.csv", "per_image.csv"]
POISON = 5  # in shard 2 of 4
FAULT = "TORCHSAR_TEST_FAULT"


class Chips(torch.utils.data.Dataset):
    """Eight simulated chips, generated on demand (picklable for worker processes)."""

    def __len__(self) -> int:
        return 8

    def __getitem__(self, i: int) -> dict:
        item = ts.simulate.chips(1, size=48, length_px=(10, 16), seed=5, start=i)[0]
        item["meta"] = {"name": str(i), **item["meta"]}
        return item


def fragile(x, meta=None):
    """CA-CFAR that fails on image ``POISON`` while the fault variable is set: ``raise``
    raises, ``exit`` kills its process (as the out-of-memory killer would)."""
    if any(m["index"] == POISON for m in meta) and os.environ.get(FAULT):
        if os.environ[FAULT] == "exit":
            os._exit(3)
        raise RuntimeError("poisoned image")
    return BUILTIN["ca"](x)


def _run(out, **kwargs):
    kwargs.setdefault("execution", Execution(batch_size=2, shard_size=2, progress=False))
    detectors = kwargs.pop("detectors", [Detector("fragile", fragile)])
    return evaluate({"chips": Chips()}, detectors, out=out, **kwargs)


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    out = tmp_path_factory.mktemp("whole") / "run"
    _run(out)
    return out


def _kept(parent):
    (h,) = hidden_folders(parent)
    assert not h.alive and h.resumable
    return h


def _resumed_equals_whole(out, whole, at_least: int):
    results = _run(out, resume=True)
    assert results.stats["chips"]["skipped"] >= at_least  # shards taken from the saved work
    for name in TABLES:
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name
    assert hidden_folders(out.parent) == []


def test_an_error_keeps_the_saved_shards(tmp_path, whole, monkeypatch):
    out = tmp_path / "run"
    monkeypatch.setenv(FAULT, "raise")
    with pytest.raises(EvalError, match=r"shard 2 failed: poisoned image.*kept in .*resume=True"):
        _run(out)
    assert not out.exists() and _kept(tmp_path)
    monkeypatch.delenv(FAULT)
    _resumed_equals_whole(out, whole, at_least=2)


@pytest.mark.integration
def test_a_dead_worker_keeps_the_saved_shards(tmp_path, whole, monkeypatch):
    out = tmp_path / "run"
    monkeypatch.setenv(FAULT, "exit")
    ex = Execution(batch_size=2, shard_size=2, workers=2, progress=False)
    died = "shard 2 failed: a worker process died.*kept in"
    with pytest.raises(EvalError, match=died), pytest.warns(RuntimeWarning, match="died"):
        _run(out, execution=ex)
    _kept(tmp_path)
    monkeypatch.delenv(FAULT)
    _resumed_equals_whole(out, whole, at_least=2)


@pytest.mark.parametrize("where", ["shard", "final"])
def test_a_full_disk_keeps_the_saved_shards(tmp_path, whole, monkeypatch, where):
    import torchsar_eval.api
    import torchsar_eval.statefile

    out = tmp_path / "run"
    full = OSError(errno.ENOSPC, "No space left on device")
    if where == "shard":
        real, calls = os.fsync, []

        def fsync(fd):  # the third shard file and every later one hit a full disk
            calls.append(fd)
            if len(calls) >= 3:
                raise full
            real(fd)

        monkeypatch.setattr(torchsar_eval.statefile.os, "fsync", fsync)
    else:
        monkeypatch.setattr(
            torchsar_eval.api, "write_run", lambda *a, **k: (_ for _ in ()).throw(full)
        )
    message = "cannot save shard-000002.state" if where == "shard" else "cannot write the run"
    with pytest.raises(EvalError, match=f"{message} .*No space left.*kept in"):
        _run(out)
    _kept(tmp_path)
    monkeypatch.undo()
    _resumed_equals_whole(out, whole, at_least=2 if where == "shard" else 4)


def test_a_refused_resume_and_other_runs_keep_the_saved_shards(tmp_path, whole, monkeypatch):
    out = tmp_path / "run"
    monkeypatch.setenv(FAULT, "raise")
    with pytest.raises(EvalError):
        _run(out)
    monkeypatch.delenv(FAULT)
    kept = _kept(tmp_path).path
    with pytest.raises(EvalError, match="options differ.*kept in"):
        _run(out, resume=True, detectors=[Detector("fragile", fragile), "so"])
    with pytest.raises(EvalError, match="saved work .*resume=True.*discard=True"):
        _run(out)  # a new run would make the saved work useless: refused
    with pytest.warns(StaleRunWarning, match="--resume --out"):
        _run(tmp_path / "other", detectors=["ca"])  # another run beside it lists it, keeps it
    assert _kept(tmp_path).path != kept  # adopted by the refused resume, kept under its name
    _resumed_equals_whole(out, whole, at_least=2)


def test_discard_starts_over(tmp_path, whole, monkeypatch):
    out = tmp_path / "run"
    monkeypatch.setenv(FAULT, "raise")
    with pytest.raises(EvalError):
        _run(out)
    monkeypatch.delenv(FAULT)
    results = _run(out, discard=True)
    assert results.stats["chips"]["skipped"] == 0
    assert (out / "summary.csv").read_bytes() == (whole / "summary.csv").read_bytes()
    assert hidden_folders(tmp_path) == []
