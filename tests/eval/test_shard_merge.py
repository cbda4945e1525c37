"""Saved shards are merged in shard order while the rest are scored: whatever order they
arrive in, and past lost ones, the merge and its per-image rows are those of merging the
folder at the end."""

from __future__ import annotations

import random
import shutil

import pandas as pd
import pytest

import torchsar_eval as te
from torchsar_eval.datasets import make_dataset
from torchsar_eval.registry import BUILTIN
from torchsar_eval.shard_states import (
    ROWS_FILE,
    ShardMerger,
    load_shard,
    merge,
    shard_files,
    shard_path,
    shard_rows,
)
from torchsar_eval.shards import ShardJob, run_shards
from torchsar_eval.tables import summary_table


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A folder of 5 saved shards (9 chips, shards of 2, two detectors)."""
    job = ShardJob(
        "chips",
        make_dataset("sim-chips", n=9),
        list(range(9)),
        [BUILTIN["ca"], BUILTIN["so"]],
        te.Scoring(replicates=5),
        te.Execution(batch_size=2, shard_size=2, progress=False),
    )
    folder = tmp_path_factory.mktemp("saved")
    run_shards(job, folder)
    return folder


def _copy(folder, to, keep=None):
    to.mkdir()
    for p in shard_files(folder):
        if keep is None or int(p.stem.split("-")[1]) in keep:
            shutil.copy(p, to / p.name)
    return to


def _reference(folder, tmp_path):
    with open(tmp_path / "ref-rows", "w") as f:
        merged = merge((load_shard(p).results for p in shard_files(folder)), f)
    return summary_table({"d": merged}), (tmp_path / "ref-rows").read_text()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_any_arrival_order_merges_as_the_folder_does(saved, tmp_path, seed):
    folder = _copy(saved, tmp_path / "f")
    want_table, want_rows = _reference(folder, tmp_path)
    order = list(range(5))
    random.Random(seed).shuffle(order)
    already = order[:2]  # saved by an earlier run
    with ShardMerger(folder, 5, [k for k in order if k not in already]) as merger:
        for k in order[2:]:
            merger.saved(k)
        merged = merger.finish()
    pd.testing.assert_frame_equal(summary_table({"d": merged}), want_table)
    assert (folder / ROWS_FILE).read_text() == want_rows
    assert sorted(p.name for p in folder.iterdir() if p.name.startswith(".")) == []


def test_a_lost_shard_is_merged_past(saved, tmp_path):
    folder = _copy(saved, tmp_path / "f", keep={0, 1, 3, 4})
    want_table, want_rows = _reference(folder, tmp_path)
    with ShardMerger(folder, 5, [0, 1, 2, 3, 4]) as merger:
        for k in (3, 0, 4):
            merger.saved(k)
        merger.lost(2)
        merger.saved(1)
        merged = merger.finish()
    pd.testing.assert_frame_equal(summary_table({"d": merged}), want_table)
    assert [d for d, _ in shard_rows(folder)] == ["ca", "so"] * 4
    assert (folder / ROWS_FILE).read_text() == want_rows


def test_a_shard_not_seen_as_it_was_saved_is_merged_at_the_end(saved, tmp_path):
    folder = _copy(saved, tmp_path / "f")
    want_table, want_rows = _reference(folder, tmp_path)
    with ShardMerger(folder, 5, [0, 1, 2, 3, 4]) as merger:
        for k in (0, 1, 2, 4):  # shard 3 is saved, but nobody said so
            merger.saved(k)
        merged = merger.finish()
    pd.testing.assert_frame_equal(summary_table({"d": merged}), want_table)
    assert (folder / ROWS_FILE).read_text() == want_rows


def test_a_failed_run_leaves_no_rows(saved, tmp_path):
    folder = _copy(saved, tmp_path / "f")
    (folder / ROWS_FILE).write_text("stale\n")
    with pytest.raises(RuntimeError, match="stop"), ShardMerger(folder, 5, [3]) as merger:
        merger.saved(3)
        raise RuntimeError("stop")
    assert not (folder / ROWS_FILE).exists()
    assert [p.name for p in folder.iterdir() if not p.name.startswith("shard-")] == []
    assert shard_path(folder, 3).exists()
