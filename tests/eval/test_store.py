"""Stored datasets: item i of a store is item i of its source, read lazily."""

from __future__ import annotations

import io
import json
import pickle
import subprocess
import sys
import tarfile

import numpy as np
import pytest
import torch

import torchsar as ts
from torchsar_eval.cli import main
from torchsar_eval.commands.make_dataset import sim_items
from torchsar_eval.datasets import BadItemError
from torchsar_eval.errors import EvalError
from torchsar_eval.store import (
    StoreDataset,
    lock_path,
    partial_path,
    remove_dead_partials,
    write_store,
)


def test_sim_items_equal_the_batch_generation():
    batch = ts.simulate.chips(5, seed=2)
    items = list(sim_items("sim-chips", 5, 2, block=2))
    for i, it in enumerate(items):
        for k in ("image", "mask", "instances", "ignore"):
            assert torch.equal(it[k], batch[i][k])
        assert it["meta"]["name"] == f"sim-chips/{i}"


def test_make_dataset_round_trip_and_lazy_reads(tmp_path):
    out = tmp_path / "store"
    argv = [
        "make-dataset",
        "--kind",
        "sim-chips",
        "--n",
        "7",
        "--seed",
        "4",
        "--shard-size",
        "3",
        "--out",
        str(out),
        "--no-progress",
    ]
    assert main(argv) == 0
    assert sorted(p.name for p in out.glob("*.tar")) == [f"shard-00000{k}.tar" for k in range(3)]
    ds = StoreDataset(out)
    batch = ts.simulate.chips(7, seed=4)
    assert len(ds) == 7 and ds._index is None  # nothing opened before the first read
    for i in (6, 0, 3):  # any order
        for k in ("image", "mask", "instances", "ignore"):
            assert torch.equal(ds[i][k], batch[i][k])
        assert ds[i]["meta"]["boxes"] == [list(b) for b in batch.meta[i]["boxes"]]
    assert pickle.loads(pickle.dumps(ds))._index is None  # workers get no open map
    with tarfile.open(out / "shard-000001.tar") as tar:  # the WebDataset layout
        assert tar.getnames()[:5] == [
            f"000000003.{f}"
            for f in ("image.npy", "mask.npy", "instances.npy", "ignore.npy", "json")
        ]
    header = json.loads((out / "store.json").read_text())
    assert (header["n"], header["source"], header["seed"]) == (7, "sim-chips", 4)
    assert main(argv) == 2  # the store exists: refused


def test_truncated_or_foreign_store_is_a_clear_error(tmp_path):
    b = ts.simulate.chips(2, seed=0)
    out = write_store(({**b[i], "meta": {"name": str(i)}} for i in range(2)), 2, tmp_path / "s")
    shard = out / "shard-000000.tar"
    shard.write_bytes(shard.read_bytes()[:2000])
    with pytest.raises(EvalError, match="truncated"):
        StoreDataset(out)[1]
    with pytest.raises(EvalError, match="not a torchsar store"):
        StoreDataset(tmp_path)


def test_run_on_a_store_equals_run_on_its_source(tmp_path):
    store = tmp_path / "store"
    make = ["make-dataset", "--kind", "sim-chips", "--n", "6", "--out", str(store), "--no-progress"]
    assert main(make) == 0
    common = ["--detectors", "ca", "--bootstrap", "10", "--no-progress"]
    a, b = tmp_path / "a", tmp_path / "b"
    assert main(["run", "--dataset", "sim-chips", "--n", "6", "--out", str(a), *common]) == 0
    assert main(["run", "--dataset", f"store:{store}", "--out", str(b), *common]) == 0
    for name in ("summary.csv", "roc.csv", "pr.csv", "breakdown.csv"):
        rows_a = [r.split(",", 1)[1] for r in (a / name).read_text().splitlines()]
        rows_b = [r.split(",", 1)[1] for r in (b / name).read_text().splitlines()]
        assert rows_a == rows_b, name  # all but the dataset label


def _legacy(root):
    """The first store format: index rows 0-4 (no checksum), version 1."""
    np.save(root / "index.npy", np.ascontiguousarray(np.load(root / "index.npy")[:, :5]))
    head = json.loads((root / "store.json").read_text())
    (root / "store.json").write_text(json.dumps({**head, "version": 1}))


def test_first_format_stores_still_read(tmp_path):
    src = list(sim_items("sim-chips", 3, 1))
    out = write_store(iter(src), 3, tmp_path / "s", shard_size=2)
    with tarfile.open(out / "shard-000000.tar") as tar:  # a plain tar for any reader
        member = tar.extractfile("000000001.instances.npy").read()
    assert torch.equal(torch.from_numpy(np.load(io.BytesIO(member))), src[1]["instances"])
    _legacy(out)
    ds = StoreDataset(out)
    assert ds.version == 1
    for i in range(3):
        for k in ("image", "mask", "instances", "ignore"):
            assert torch.equal(ds[i][k], src[i][k])


def test_a_short_source_or_bad_counts_are_refused(tmp_path):
    with pytest.raises(EvalError, match="the source ended after 1 of the 2 items"):
        write_store(sim_items("sim-chips", 1, 0), 2, tmp_path / "s")
    with pytest.raises(EvalError, match="shard_size=0: must be a whole number >= 1"):
        write_store([], 0, tmp_path / "s", shard_size=0)
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing left behind


HOLD = """
import sys
from torchsar_eval.locks import hold
with hold(sys.argv[1]):
    print("held", flush=True)
    sys.stdin.read()
"""


def test_only_dead_writers_partial_stores_are_removed(tmp_path):
    live, dead = tmp_path / "live", tmp_path / "dead"
    for out in (live, dead):
        partial_path(out).mkdir()
        (partial_path(out) / "shard-000000.tar").write_bytes(b"x")
    lock_path(dead).write_text("")  # a killed writer's lock file: there, but free
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(lock_path(live))],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout.readline().strip() == "held"
        assert remove_dead_partials(tmp_path) == [partial_path(dead)]
        assert partial_path(live).is_dir() and not lock_path(dead).exists()
    finally:
        proc.stdin.close()
        proc.wait()
    assert remove_dead_partials(tmp_path) == [partial_path(live)]
    assert list(tmp_path.iterdir()) == []


def test_a_store_changed_after_opening_is_named_at_read(tmp_path):
    out = write_store(sim_items("sim-chips", 2, 0), 2, tmp_path / "s")
    ds = StoreDataset(out)  # checked here ...
    index = np.load(out / "index.npy")
    index[1, 0, 0] = 10**13
    np.save(out / "index.npy", index)  # ... then changed before the first read
    assert torch.equal(ds[0]["image"], next(sim_items("sim-chips", 1, 0))["image"])
    with pytest.raises(BadItemError, match=r"shard-000000.tar: item 000000001: .*changed since"):
        ds[1]
    with pytest.raises(EvalError, match=r"n=-1: must be a whole number >= 0"):
        StoreDataset(out, limit=-1)


def test_a_retry_after_a_killed_writer_replaces_its_partial_store(tmp_path):
    """What a SIGKILLed make-dataset leaves (its partial store, its free lock file): the
    next write into the same --out removes it and succeeds (before: a FileExistsError
    traceback on every retry, the partial left)."""

    out = tmp_path / "s"
    left = partial_path(out)
    (left / "shards").mkdir(parents=True)
    (left / "shards" / "shard-000000.tar").write_bytes(b"x" * 1000)
    lock_path(out).write_text("")
    assert write_store(sim_items("sim-chips", 2, 0), 2, out) == out
    assert StoreDataset(out).version >= 1 and len(StoreDataset(out)) == 2
    assert not left.exists()


def test_a_full_disk_is_one_line_and_leaves_nothing(tmp_path, monkeypatch, capsys):
    import errno

    import torchsar_eval.store as store

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(store, "_write_folder", full)
    code = main(
        [
            "make-dataset",
            "--kind",
            "sim-chips",
            "--n",
            "2",
            "--no-progress",
            "--out",
            str(tmp_path / "s"),
        ]
    )
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "No space left on device" in err, err
    assert not [p for p in tmp_path.iterdir() if not p.name.endswith(".store-lock")]
