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
from torchsar_eval.shard_states import ShardState, load_shard
from torchsar_eval.shards import run_shards
from torchsar_eval.tables import summary_table


class _Marker:
    """Unpickling this creates a file: the proof that a state file ran code."""

    def __init__(self, path) -> None:
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def _one_run(tmp_path, **scoring):
    return te.evaluate(
        "sim-chips",
        ["ca", "region"],
        n=5,
        progress=False,
        scoring=te.Scoring(replicates=10, **scoring),
    )


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

    job = ShardJob(
        "chips",
        make_dataset("sim-chips", n=4),
        list(range(4)),
        [BUILTIN["ca"]],
        te.Scoring(replicates=0),
        te.Execution(batch_size=2, shard_size=2, progress=False),
    )
    folder = tmp_path / "shards"
    folder.mkdir()
    payload = zlib.compress(pickle.dumps(_Marker(marker)), 1)
    (folder / "shard-000000.state").write_bytes(payload)  # where a state is looked for
    (folder / "shard-000001.pkl").write_bytes(payload)  # the old name
    with pytest.warns(RuntimeWarning, match="not a readable torchsar state"):
        merged, counts = run_shards(job, folder)
    assert not marker.exists()
    assert counts["done"] == 2 and merged[0].images == 4


def _pack(header: dict, tree, arrays: list) -> bytes:
    body = zlib.compress(statefile.pack(tree, arrays), 1)
    if header.get("blake2b") == "recompute":
        header = {**header, "blake2b": statefile._digest(body)}
    return statefile.MAGIC + json.dumps(header).encode() + b"\n" + body


def _unpack(data: bytes) -> tuple[dict, object, list]:
    line, _, body = data[len(statefile.MAGIC) :].partition(b"\n")
    tree, arrays = statefile.unpack(zlib.decompress(body))
    return json.loads(line), tree, [a.copy() for a in arrays]


@pytest.mark.parametrize("how", ["array", "structure", "truncated", "version", "magic"])
def test_changed_states_are_refused(tmp_path, how):
    path = tmp_path / "s.state"
    res = _one_run(tmp_path)
    data = statefile.dumps(ShardState(res.states["sim-chips"]))
    header, tree, arrays = _unpack(data)
    if how == "array":
        a = next(a for a in arrays if a.size)
        a.reshape(-1).view(np.uint8)[0] ^= 1
        data = _pack(header, tree, arrays)
    elif how == "structure":
        text = json.dumps(tree).replace("PixelCounts", "PixelCounts ")
        data = _pack(header, json.loads(text), arrays)
    elif how == "version":
        data = _pack({**header, "version": 99, "blake2b": "recompute"}, tree, arrays)
    elif how == "magic":
        data = data[1:]
    else:
        data = data[: len(data) // 2]
    path.write_bytes(data)
    with pytest.raises(statefile.CorruptStateError, match="s.state"):
        load_shard(path)


def _recompute(body: bytes, version: int = statefile.VERSION) -> bytes:
    header = {"format": statefile.FORMAT, "version": version, "blake2b": statefile._digest(body)}
    return statefile.MAGIC + json.dumps(header).encode() + b"\n" + body


@pytest.mark.parametrize(
    "entry",
    [
        [0, "|O", [1]],  # an object array: never
        [0, "<f8", [10**6]],  # past the end of the body
        [-64, "<f8", [1]],
        [0, "<f8", [-1]],
        [0, "<f8", "12"],
        [0, ["<f8"], [1]],
        [0, "V8", [1]],
        [0, [["a", "|O"]], [1]],  # nor inside a record
        [0, [["a", "<f8", [-1]]], [1]],
        [0, [["a", "|V8"]], [1]],  # raw bytes only as unnamed padding
        "a0",
    ],
)
def test_an_array_table_out_of_bounds_or_of_other_types_is_refused(entry):
    """Even with a valid hash, the table names only plain arrays inside the body."""
    raw = bytearray(statefile.pack({"__array__": 0}, [np.arange(3.0)]))
    n = int.from_bytes(raw[:8], "little")
    head = json.loads(raw[8 : 8 + n])
    head["arrays"] = [entry]
    text = json.dumps(head).encode()
    raw = len(text).to_bytes(8, "little") + text + bytes(64) * 2
    with pytest.raises(statefile.CorruptStateError, match="unexpected|past the end"):
        statefile.loads(_recompute(zlib.compress(raw)), "crafted")


def test_records_and_odd_layouts_come_back_equal():
    rec = np.dtype([("score", "<f8"), ("bits", "u1", (3,)), ("sub", [("a", "<f4"), ("b", ">i2")])])
    a = np.zeros(4, rec)
    a["score"], a["sub"]["b"] = [1, 2, 3, 4], [5, -6, 7, 8]
    padded = np.dtype({"names": ["x", "y"], "formats": ["u1", "<f8"], "offsets": [0, 8]})
    values = [
        a,
        np.ones(2, padded),
        np.arange(12.0).reshape(3, 4)[:, ::2],
        np.array(5.0),
        np.zeros((0, 3), np.float32),
        np.array([True, False]),
    ]
    for v, b in zip(values, statefile.loads(statefile.dumps(values), "test"), strict=True):
        assert b.dtype == v.dtype and b.shape == v.shape and np.array_equal(b, v)
        assert b.flags.writeable and b.flags.owndata  # no view keeping a whole file alive


def test_version_1_files_are_still_read():
    """A run saved before the raw-array body (an NPZ archive body) resumes without
    rescoring."""
    value = {"counts": np.arange(5, dtype=np.int64), "grid": torch.linspace(0, 1, 4)}
    enc = statefile._Encoder()
    tree = enc(value)
    buf = io.BytesIO()
    named = {f"a{i}": a for i, a in enumerate(enc.arrays)}
    text = json.dumps(tree).replace('__array__": 0', '__array__": "a0"')
    text = text.replace('__tensor__": 1', '__tensor__": "a1"')
    np.savez(buf, __structure__=np.frombuffer(text.encode(), np.uint8), **named)
    back = statefile.loads(_recompute(zlib.compress(buf.getvalue(), 1), version=1), "v1")
    assert np.array_equal(back["counts"], value["counts"]) and back["counts"].dtype == np.int64
    assert torch.equal(back["grid"], value["grid"])


def test_only_allow_listed_types_are_written():
    with pytest.raises(TypeError, match="not a state type"):
        statefile.dumps(_Marker("x"))
    with pytest.raises(TypeError, match="object arrays"):
        statefile.dumps(np.array([object()]))


def test_a_valid_hash_does_not_let_a_foreign_type_in(tmp_path):
    """Even a file whose hash was recomputed cannot name a class off the allow-list."""
    tree = {"__type__": "subprocess.Popen", "state": {"__dict__": [["args", "id"]]}}
    header = {"format": statefile.FORMAT, "version": statefile.VERSION, "blake2b": "recompute"}
    with pytest.raises(statefile.CorruptStateError, match="unexpected structure"):
        statefile.loads(_pack(header, tree, []), "crafted")


@pytest.mark.parametrize("dtype", [np.int64, np.uint64])
def test_wide_integer_arrays_come_back_in_their_own_type_and_values(dtype):
    info = np.iinfo(dtype)
    arrays = [
        np.array(v, dtype=dtype)
        for v in ([0, 1, 127], [200, 0], [70_000], [info.max, 0], [info.min, 3], [])
    ]
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
    header, tree, arrays = _unpack(statefile.dumps(np.arange(3, dtype=np.int64)))
    tree["__as__"] = "<f8"
    with pytest.raises(statefile.CorruptStateError, match="unexpected"):
        statefile.loads(_pack({**header, "blake2b": "recompute"}, tree, arrays), "test")


@pytest.mark.parametrize(
    "rows",
    [
        [("a", 1, 1, 0, 0, 2, 0.5), ("b", 0, 0, 1, 0, 1, float("-inf"))],
        [],
        [("odd", 1)],
    ],
)
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

    job = ShardJob(
        "chips",
        make_dataset("sim-chips", n=7),
        list(range(7)),
        [BUILTIN["ca"], BUILTIN["so"]],
        te.Scoring(replicates=0),
        te.Execution(batch_size=2, shard_size=3, progress=False),
    )
    folder = tmp_path / "shards"
    run_shards(job, folder)
    written = [(d, [tuple(r) for r in rows]) for d, rows in shard_rows(folder)]
    (folder / ROWS_FILE).unlink()
    saved = list(shard_rows(folder))  # read from the states
    assert written == saved and len(saved) == 3 * 2  # shards x detectors
    assert sum(len(rows) for _, rows in saved) == 7 * 2
