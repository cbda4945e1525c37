"""``scripts/interval_coverage.py``: datasets re-formed from the records of a scored pool
are the scored datasets (the same points, replicate spreads and counts), so rules judged on
re-formed and drawn datasets are judged on what the harness computes."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from tests.scripts import load_script


@pytest.fixture(scope="module")
def cov():
    return load_script("interval_coverage")


@pytest.fixture(scope="module")
def run(cov, tmp_path_factory):
    out = tmp_path_factory.mktemp("cov") / "chips"
    args = argparse.Namespace(
        kind="sim-chips",
        sizes=[2, 4],
        datasets=2,
        detectors=["region"],
        replicates=30,
        seed=3,
        out=str(out),
    )
    cov.score(args)
    return out


def test_blocks_re_formed_from_the_records_are_the_scored_datasets(cov, run):
    scored = [json.loads(x) for x in (run / "records.jsonl").read_text().splitlines()]
    truth, formed = cov.formed(str(run), 0)
    assert len(formed) == len(scored) == 4 + 2
    key = lambda r: (r["detector"], r["size"], r["dataset"])  # noqa: E731
    by = {key(r): r for r in formed}
    for r in scored:
        f = by[key(r)]
        assert not f["drawn"] and len(f["unit_tp"]) == r["units"] == r["size"]
        for k in ("units", "n_gt", "tp", "fp"):
            assert f[k] == r[k], k
        assert sum(f["unit_tp"]) == r["tp"] and sum(f["unit_gt"]) == r["n_gt"]
        for m in cov.METRICS:
            for k in ("point", "mean", "var", "used", "undefined", "pct"):
                assert f[m][k] == pytest.approx(r[m][k], rel=1e-12, nan_ok=True), (m, k)
    state = cov.statefile.loads((run / "truth.state").read_bytes())["region"].metrics()
    assert {m: truth["region"][m] for m in cov.METRICS} == pytest.approx(
        {m: state[m] for m in cov.METRICS}, nan_ok=True
    )


def test_draws_top_each_size_up_and_are_cached(cov, run):
    _, formed = cov.formed(str(run), 5)
    for n in (2, 4):
        rs = [r for r in formed if r["size"] == n]
        assert len(rs) == 5 and sum(r["drawn"] for r in rs) == 5 - 8 // n
        assert all(r["units"] == n == len(r["unit_gt"]) for r in rs)
    again = cov.formed(str(run), 5)[1]  # cached: the same datasets
    assert [r["recall"]["var"] for r in again] == [r["recall"]["var"] for r in formed]
    assert np.isfinite([r["precision"]["point"] for r in formed if r["tp"] + r["fp"]]).all()
