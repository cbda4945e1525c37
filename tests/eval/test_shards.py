"""Shards: any shard size, worker count or resumed run gives identical tables."""

from __future__ import annotations

import json
import os
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
import torch

import torchsar as ts
from torchsar_eval.commands.run import DEFAULT_MATCH, DEFAULT_RULES
from torchsar_eval.errors import EvalError
from torchsar_eval.registry import BUILTIN
from torchsar_eval.result import Scoring
from torchsar_eval.settings import Execution
from torchsar_eval.shards import ShardJob, run_shards, shard_coco, shard_ranges, shard_rows
from torchsar_eval.tables import (
    breakdown_table,
    errors_table,
    froc_table,
    paired_table,
    pixel_roc_table,
    pr_table,
    scr_table,
    summary_table,
)


class Chips(torch.utils.data.Dataset):
    """Simulated chips generated on demand (picklable: no tensors held)."""

    def __init__(self, n: int) -> None:
        self.n = n

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, i: int) -> dict:
        item = ts.simulate.chips(1, size=64, length_px=(12, 24), seed=3, start=i)[0]
        item["meta"] = {"name": str(i), **item["meta"]}
        return item


def _tables(results) -> list[pd.DataFrame]:
    r = {"chips": results}
    return [
        f(r)
        for f in (
            summary_table,
            froc_table,
            pr_table,
            pixel_roc_table,
            breakdown_table,
            scr_table,
            errors_table,
            paired_table,
        )
    ]


def _job(n: int, shard_size: int, export_coco: bool = False) -> ShardJob:
    specs = [BUILTIN["ca"], BUILTIN["so"]]
    scoring = Scoring(DEFAULT_RULES, DEFAULT_MATCH, replicates=10)
    return ShardJob(
        "chips",
        Chips(n),
        list(range(n)),
        specs,
        scoring,
        _ex(batch_size=3, shard_size=shard_size),
        export_coco=export_coco,
    )


def _ex(**kw) -> Execution:
    """A quiet execution (no progress bar)."""
    return Execution(**{"progress": False, **kw})


_EX2 = Execution(batch_size=2, shard_size=2, progress=False)


def _one(dataset, detector) -> ShardJob:
    """One detector on all of ``dataset``, batches and shards of 2."""
    return ShardJob(
        "chips", dataset, list(range(len(dataset))), [detector], _job(6, 2).scoring, _EX2
    )


def _on(job: ShardJob, **kw) -> ShardJob:
    """``job`` run with other execution settings (workers, engine, skip_bad)."""
    return replace(job, execution=replace(job.execution, **kw))


def _coco_json(folder) -> dict[str, str]:
    out = folder / "coco"
    paths = shard_coco(folder, "chips").write(out, "chips")
    return {p.name: p.read_text() for p in paths}


def _rows(folder) -> dict[str, list]:
    out: dict[str, list] = {}
    for det, rows in shard_rows(folder):
        out.setdefault(det, []).extend(rows)
    return out


def _assert_same(a, b, folder_a=None, folder_b=None) -> None:
    for x, y in zip(_tables(a), _tables(b), strict=True):
        pd.testing.assert_frame_equal(x, y)
    for ra, rb in zip(a, b, strict=True):  # the worst-case galleries too
        for ca, cb in (
            (ra.gallery.false_alarms, rb.gallery.false_alarms),
            (ra.gallery.misses, rb.gallery.misses),
        ):
            assert ca.keys == cb.keys and ca.info == cb.info
            assert np.array_equal(ca.image, cb.image, equal_nan=True)
            assert np.array_equal(ca.masks, cb.masks)
    if folder_a is not None:
        rows = _rows(folder_a)
        assert rows == _rows(folder_b) and all(len(v) == a[0].images for v in rows.values())


def test_shard_ranges_cover_every_item_once():
    assert [list(r) for r in shard_ranges(7, 3)] == [[0, 1, 2], [3, 4, 5], [6]]
    assert shard_ranges(0, 5) == []


@pytest.mark.parametrize("size", [1, 4])
def test_any_shard_size_gives_the_same_tables(tmp_path, size):
    whole, counts = run_shards(_job(9, 100), tmp_path / "a")
    parts, counts_p = run_shards(_job(9, size), tmp_path / "b")
    assert counts == {
        "shards": 1,
        "done": 1,
        "skipped": 0,
        "retried": 0,
        "failed": [],
        "scored_images": 9,
        "reused_images": 0,
    }
    assert counts_p["shards"] == -(-9 // size)
    _assert_same(whole, parts, tmp_path / "a", tmp_path / "b")


def test_resume_skips_saved_shards_and_changes_nothing(tmp_path):
    first, _ = run_shards(_job(8, 3), tmp_path)
    (tmp_path / "shard-000001.state").unlink()  # as if killed before shard 1 was saved
    again, counts = run_shards(_job(8, 3), tmp_path)
    assert counts == {
        "shards": 3,
        "done": 1,
        "skipped": 2,
        "retried": 0,
        "failed": [],
        "scored_images": 3,
        "reused_images": 5,
    }  # shard 1 scored again
    _assert_same(first, again)


@pytest.mark.integration
def test_coco_export_is_the_same_for_any_sharding_workers_and_resume(tmp_path):
    """The export travels with the shard states: one pass, small shards over two workers,
    and a run resumed after losing a shard all write the same COCO files."""
    run_shards(_job(7, 100, True), tmp_path / "one")
    run_shards(_on(_job(7, 2, True), workers=2), tmp_path / "two")
    (tmp_path / "two" / "shard-000001.state").unlink()  # as if killed before it was saved
    _, counts = run_shards(_job(7, 2, True), tmp_path / "two")
    assert counts["done"] == 1 and counts["skipped"] == 3
    one, two = _coco_json(tmp_path / "one"), _coco_json(tmp_path / "two")
    assert one == two and set(one) == {"chips__gt.json", "chips__ca.json", "chips__so.json"}
    gt = json.loads(one["chips__gt.json"])
    assert [im["id"] for im in gt["images"]] == list(range(1, 8))
    assert [a["id"] for a in gt["annotations"]] == list(range(1, len(gt["annotations"]) + 1))
    assert len(json.loads(one["chips__ca.json"])) > 0


@pytest.mark.integration
def test_two_workers_equal_one(tmp_path):
    one, _ = run_shards(_job(6, 2), tmp_path / "one")
    two, _ = run_shards(_on(_job(6, 2), workers=2), tmp_path / "two")
    _assert_same(one, two, tmp_path / "one", tmp_path / "two")


def _explode_on_big(x):
    if float(x.max()) > 1e30:
        raise RuntimeError("corrupt shard")
    return BUILTIN["ca"](x)


class Poisoned(Chips):
    """Chips whose item 4 is corrupt."""

    def __getitem__(self, i: int) -> dict:
        item = super().__getitem__(i)
        if i == 4:
            item["image"] = item["image"] * 0 + 1e38
        return item


class Unreadable(Chips):
    """Chips whose item 4 cannot be read (an error outside any detector's batch)."""

    def __getitem__(self, i: int) -> dict:
        if i == 4:
            raise RuntimeError("corrupt shard")
        return super().__getitem__(i)


def test_failed_shard_stops_the_run_or_is_skipped_and_named(tmp_path):
    job = _one(Unreadable(6), BUILTIN["ca"])
    with pytest.raises(EvalError, match="shard 2 failed: corrupt shard"):
        run_shards(job, tmp_path / "a")
    merged, counts = run_shards(_on(job, skip_bad=True), tmp_path / "b")
    assert counts["failed"] == [{"shard": 2, "error": "RuntimeError: corrupt shard"}]
    assert merged[0].images == 4  # the other shards, merged


def test_with_skip_bad_a_failing_batch_loses_only_its_bad_image(tmp_path):
    """The same option reaches the batches: the detector's failure on item 4 skips that
    image alone (its batch scored again image by image), and no shard fails."""
    from torchsar_eval.detector import Detector

    job = _one(Poisoned(6), Detector("x", _explode_on_big))
    with pytest.raises(EvalError, match="shard 2 failed: corrupt shard"):
        run_shards(job, tmp_path / "a")
    merged, counts = run_shards(_on(job, skip_bad=True), tmp_path / "b")
    assert counts["failed"] == [] and merged[0].images == 5
    assert len(merged[0].skipped) == 1 and "corrupt shard" in merged[0].skipped[0][1]


def _fail_first_time(x, marker):
    """Fails on the first call for a shard whose first image is item 2 (any process), then
    works: a transient fault."""
    if float(x[0].sum()) == float(_FLAKY_SUM) and not marker.exists():
        marker.touch()
        raise RuntimeError("transient")
    return BUILTIN["ca"](x)


def _die_on_big(x):
    if float(x.max()) > 1e30:
        os._exit(3)  # the worker process dies, as under the OOM killer
    return BUILTIN["ca"](x)


_FLAKY_SUM = float(Chips(3)[2]["image"].sum())


@pytest.mark.parametrize(
    "engine,workers",
    [
        ("local", 1),
        pytest.param("local", 2, marks=pytest.mark.integration),
        pytest.param("ray", 1, marks=pytest.mark.integration),
    ],
)  # worker pools and Ray: integration tests (CI's second step)
def test_a_transient_failure_is_retried_once_and_counted(tmp_path, engine, workers):
    from functools import partial

    from torchsar_eval.detector import Detector

    if engine == "ray":
        pytest.importorskip("ray")
    spec = Detector("ca", partial(_fail_first_time, marker=tmp_path / "failed-once"))
    job = _one(Chips(6), spec)
    run = tmp_path / "run"
    merged, counts = run_shards(_on(job, workers=workers, engine=engine), run)
    assert (tmp_path / "failed-once").exists()
    assert counts["retried"] == 1 and counts["failed"] == [] and counts["done"] == 3
    assert merged[0].images == 6


@pytest.mark.integration
def test_a_dead_worker_fails_its_own_shard_only(tmp_path):
    """The shard that kills its worker is told apart from those that shared the pool with
    it (run again, each in a fresh process), and fails alone; the others are scored."""
    from torchsar_eval.detector import Detector

    job = _one(Poisoned(6), Detector("x", _die_on_big))
    with pytest.warns(RuntimeWarning, match="worker process died.*again one at a time"):
        merged, counts = run_shards(_on(job, workers=2, skip_bad=True), tmp_path / "run")
    assert [f["shard"] for f in counts["failed"]] == [2]
    assert "worker process died" in counts["failed"][0]["error"]
    assert merged[0].images == 4 and counts["done"] == 2
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == [
        "rows.jsonl",
        "shard-000000.state",
        "shard-000001.state",
    ]
    alone = ShardJob("chips", Poisoned(6), [4, 5], job.detectors, job.scoring, _EX2)
    with (  # without skip_bad it stops the run (the poisoned shard alone: fewer processes)
        pytest.raises(EvalError, match="shard 0 failed: a worker process died"),
        pytest.warns(RuntimeWarning),
    ):
        run_shards(_on(alone, workers=2), tmp_path / "again")


@pytest.mark.integration
def test_ray_engine_equals_local(tmp_path):
    pytest.importorskip("ray")
    local, _ = run_shards(_job(6, 2), tmp_path / "local")
    remote, counts = run_shards(_on(_job(6, 2), engine="ray"), tmp_path / "ray")
    assert counts["done"] == 3
    _assert_same(local, remote)
