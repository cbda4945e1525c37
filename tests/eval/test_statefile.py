"""Shard states are data only: written and read back without pickle, content-hashed, and a
planted, changed or foreign file is refused (a shard is scored again) without running any
of its code."""

from __future__ import annotations

import io
import json
import pickle
import zlib

import numpy as np
import pandas as pd
import pytest
import torch

import torchsar_eval as te
from torchsar_eval import statefile
from torchsar_eval.shards import ShardState, _load, run_shards
from torchsar_eval.tables import summary_table


class _Marker:
    """Unpickling this creates a file: the proof that a state file ran code."""

    def __init__(self, path) -> None:
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def _one_run(tmp_path, **scoring):
    return te.evaluate("sim-chips", ["ca", "region"], n=5, progress=False,
                       scoring=te.Scoring(replicates=10, **scoring))  # fmt: skip


def test_state_round_trip_keeps_every_table(tmp_path):
    res = _one_run(tmp_path, coco_compatible=True)
    states = res.states["sim-chips"]
    again = statefile.loads(statefile.dumps(ShardState(states)), "test").results
    for a, b in zip(states, again, strict=True):
        b.detector = a.detector
        assert a.objects == b.objects and a.pixels == b.pixels
        assert a.coco == b.coco
    pd.testing.assert_frame_equal(summary_table({"d": states}), summary_table({"d": again}))


def test_a_planted_pickle_runs_nothing_and_the_shard_is_scored_again(tmp_path):
    marker = tmp_path / "pwned"
    from torchsar_eval.datasets import make_dataset
    from torchsar_eval.registry import BUILTIN
    from torchsar_eval.shards import ShardJob

    job = ShardJob("chips", make_dataset("sim-chips", n=4), list(range(4)), [BUILTIN["ca"]],
                   te.Scoring(replicates=0), 2, None, 2)  # fmt: skip
    folder = tmp_path / "shards"
    folder.mkdir()
    payload = zlib.compress(pickle.dumps(_Marker(marker)), 1)
    (folder / "shard-000000.state").write_bytes(payload)  # where a state is looked for
    (folder / "shard-000001.pkl").write_bytes(payload)  # the old name
    with pytest.warns(RuntimeWarning, match="not a readable torchsar state"):
        merged, counts = run_shards(job, folder, progress=False)
    assert not marker.exists()
    assert counts["done"] == 2 and merged[0].images == 4


def _pack(header: dict, members: dict) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **members)
    body = zlib.compress(buf.getvalue(), 1)
    if header.get("blake2b") == "recompute":
        header = {**header, "blake2b": statefile._digest(body)}
    return statefile.MAGIC + json.dumps(header).encode() + b"\n" + body


def _unpack(data: bytes) -> tuple[dict, dict]:
    line, _, body = data[len(statefile.MAGIC) :].partition(b"\n")
    with np.load(io.BytesIO(zlib.decompress(body)), allow_pickle=False) as npz:
        return json.loads(line), {k: npz[k] for k in npz.files}


@pytest.mark.parametrize("how", ["array", "structure", "truncated", "version", "magic"])
def test_changed_states_are_refused(tmp_path, how):
    path = tmp_path / "s.state"
    res = _one_run(tmp_path)
    data = statefile.dumps(ShardState(res.states["sim-chips"]))
    header, members = _unpack(data)
    if how == "array":
        key = next(k for k in members if not k.startswith("__") and members[k].size)
        members[key] = members[key].copy()
        members[key].reshape(-1).view(np.uint8)[0] ^= 1
        data = _pack(header, members)
    elif how == "structure":
        text = members["__structure__"].tobytes().replace(b"PixelCounts", b"PixelCounts ")
        members["__structure__"] = np.frombuffer(text, np.uint8)
        data = _pack(header, members)
    elif how == "version":
        data = _pack({**header, "version": 99, "blake2b": "recompute"}, members)
    elif how == "magic":
        data = data[1:]
    else:
        data = data[: len(data) // 2]
    path.write_bytes(data)
    with pytest.raises(statefile.CorruptStateError, match="s.state"):
        _load(path)


def test_only_allow_listed_types_are_written():
    with pytest.raises(TypeError, match="not a state type"):
        statefile.dumps(_Marker("x"))
    with pytest.raises(TypeError, match="object arrays"):
        statefile.dumps(np.array([object()]))


def test_a_valid_hash_does_not_let_a_foreign_type_in(tmp_path):
    """Even a file whose hash was recomputed cannot name a class off the allow-list."""
    structure = json.dumps({"__type__": "subprocess.Popen",
                            "state": {"__dict__": [["args", "id"]]}})  # fmt: skip
    header = {"format": statefile.FORMAT, "version": statefile.VERSION, "blake2b": "recompute"}
    data = _pack(header, {"__structure__": np.frombuffer(structure.encode(), np.uint8)})
    with pytest.raises(statefile.CorruptStateError, match="unexpected structure"):
        statefile.loads(data, "crafted")


@pytest.mark.parametrize("dtype", [np.int64, np.uint64])
def test_wide_integer_arrays_come_back_in_their_own_type_and_values(dtype):
    info = np.iinfo(dtype)
    arrays = [np.array(v, dtype=dtype) for v in (
        [0, 1, 127], [200, 0], [70_000], [info.max, 0], [info.min, 3], [])]  # fmt: skip
    if dtype is np.int64:
        arrays += [np.array([-128, 127], dtype), np.array([-(2**31), 2**31 - 1], dtype)]
    tensors = [torch.from_numpy(a.astype(np.int64)) for a in arrays if dtype is np.int64]
    back = statefile.loads(statefile.dumps((arrays, tensors)), "test")
    for a, b in zip(arrays, back[0], strict=True):
        assert b.dtype == a.dtype and np.array_equal(a, b)
    for a, b in zip(tensors, back[1], strict=True):
        assert b.dtype == a.dtype and torch.equal(a, b)


def test_small_counts_are_stored_narrow():
    counts = np.zeros((200, 1000), np.int64)
    counts[:, ::7] = 3
    assert len(statefile.dumps(counts)) < len(statefile.dumps(counts.astype(np.float64))) / 4


def test_a_stored_type_other_than_a_wide_integer_is_refused():
    data = statefile.dumps(np.arange(3, dtype=np.int64))
    body = data[len(statefile.MAGIC) :].partition(b"\n")[2]
    raw = zlib.decompress(body)
    with np.load(io.BytesIO(raw), allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    tree = json.loads(arrays.pop("__structure__").tobytes())
    tree["__as__"] = "<f8"
    buf = io.BytesIO()
    np.savez(buf, __structure__=np.frombuffer(json.dumps(tree).encode(), np.uint8), **arrays)
    body = zlib.compress(buf.getvalue(), 1)
    head = json.dumps({"format": statefile.FORMAT, "version": statefile.VERSION,
                       "blake2b": statefile._digest(body)}).encode()  # fmt: skip
    with pytest.raises(statefile.CorruptStateError, match="unexpected"):
        statefile.loads(statefile.MAGIC + head + b"\n" + body, "test")


@pytest.mark.parametrize("rows", [
    [("a", 1, 1, 0, 0, 2, 0.5), ("b", 0, 0, 1, 0, 1, float("-inf"))],
    [],
    [("odd", 1)],
])  # fmt: skip
def test_per_image_rows_come_back_as_the_same_tuples(rows):
    res = _one_run(None)
    result = res.states["sim-chips"][0]
    result.rows = list(rows)
    back = statefile.loads(statefile.dumps(ShardState([result])), "test").results[0]
    assert back.rows == rows
    for a, b in zip(rows, back.rows, strict=True):
        assert [type(v) for v in a] == [type(v) for v in b]


def test_rows_written_while_merging_are_the_saved_shards_rows(tmp_path):
    from torchsar_eval.datasets import make_dataset
    from torchsar_eval.registry import BUILTIN
    from torchsar_eval.shards import ROWS_FILE, ShardJob, shard_rows

    job = ShardJob("chips", make_dataset("sim-chips", n=7), list(range(7)),
                   [BUILTIN["ca"], BUILTIN["so"]], te.Scoring(replicates=0), 2, None, 3)  # fmt: skip
    folder = tmp_path / "shards"
    run_shards(job, folder, progress=False)
    written = [(d, [tuple(r) for r in rows]) for d, rows in shard_rows(folder)]
    (folder / ROWS_FILE).unlink()
    saved = list(shard_rows(folder))  # read from the states
    assert written == saved and len(saved) == 3 * 2  # shards x detectors
    assert sum(len(rows) for _, rows in saved) == 7 * 2
