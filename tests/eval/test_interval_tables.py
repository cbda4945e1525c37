"""Intervals in the run's tables: boundaries, every headline metric bounded or explained,
undefined replicates reported, few images flagged, one target per image against Jeffreys,
and the same bytes for any shard size and worker count."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy import stats

import torchsar_eval as te
from tests.eval.test_paired import DETECTORS, SIZE, Squares
from tests.eval.test_shards import _job, _on
from torchsar.detection import detection_from
from torchsar.metrics.intervals import MIN_UNITS, t_shrink
from torchsar_eval.shards import run_shards
from torchsar_eval.tables import INTERVALS, paired_table, summary_table


def _run(n=24, replicates=200, unit="image", detectors=None):
    scoring = te.Scoring(replicates=replicates, bootstrap_unit=unit)
    return te.evaluate({"sq": Squares(n)}, detectors or DETECTORS, scoring=scoring, progress=False)


@pytest.fixture(scope="module")
def results():
    return _run()


def test_perfect_counts_get_intervals_of_positive_width(results):
    """Every target found and no false alarm in any image: the bootstrap has no spread,
    yet precision, recall and F1 are not [1, 1] and false alarms per image not [0, 0]."""
    s = results.summary.set_index("detector").loc["all"]
    for k in ("precision", "recall", "f1", "pd_at_1_fa_per_image"):
        assert s[k] == 1.0 and s[f"{k}_lo"] < 1.0 and s[f"{k}_hi"] == 1.0, k
    assert s.false_alarms_per_image == 0.0
    assert s.false_alarms_per_image_lo == 0.0 and s.false_alarms_per_image_hi > 0.0


def test_every_interval_column_is_bounded_or_explained(results):
    for _, row in results.summary.iterrows():
        for k in INTERVALS:
            lo, hi, v = row[f"{k}_lo"], row[f"{k}_hi"], row[k]
            if np.isnan(lo) or np.isnan(hi):
                assert k.split("_lo")[0] in row.interval_note or np.isnan(v), (k, row.detector)
            else:
                assert lo <= v <= hi or np.isclose(v, lo) or np.isclose(v, hi), (k, lo, v, hi)


def test_undefined_replicates_are_reported():
    """A detector that fires in one image only: precision is undefined in the replicates
    that leave that image out, and the note says how many."""

    def one_image(x):
        stat = torch.zeros_like(x)
        stat[0, ..., 2:5, 2:5] = 5.0  # a false alarm in the first image of each batch
        return detection_from(stat, 1.0)

    res = _run(8, 100, detectors={"one": one_image})
    row = res.summary.iloc[0]
    reps = res.states["sq"][0].objects.replicate_metrics()["precision"]
    undefined = int(np.isnan(reps).sum())
    assert undefined > 0
    assert f"{undefined}/100 replicates undefined: precision" in row.interval_note


def test_few_images_are_flagged():
    res = _run(MIN_UNITS - 2, 50)
    assert all(f"(< {MIN_UNITS})" in n for n in res.summary.interval_note)
    assert not any(f"(< {MIN_UNITS})" in n for n in _run(MIN_UNITS, 50).summary.interval_note)


def test_group_unit_counts_groups():
    res = _run(12, 50, unit="group")
    assert res.states["sq"][0].objects.units == 3  # scenes of 4 images
    assert _run(12, 50).states["sq"][0].objects.units == 12


class OneTarget(torch.utils.data.Dataset):
    """One target per image; images ``i % 5 == 0`` hold a dim one (missed by
    :func:`bright`): recall 0.8 over independent images."""

    def __init__(self, n: int) -> None:
        self.n = n

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, i: int) -> dict:
        image = torch.ones(1, SIZE, SIZE)
        inst = torch.zeros(1, SIZE, SIZE, dtype=torch.int32)
        inst[0, 10:15, 10:15] = 1
        image[inst == 1] = 100.0 if i % 5 == 0 else 300.0
        return {
            "image": image,
            "mask": inst > 0,
            "instances": inst,
            "ignore": torch.zeros(1, SIZE, SIZE, dtype=torch.bool),
            "meta": {"name": f"one/{i}"},
        }


def bright(x):
    return detection_from(x / 200.0, 1.0)


def test_one_target_per_image_agrees_with_jeffreys():
    """Independent images with one target each: recall's interval is (up to the
    bootstrap's Monte-Carlo error) Jeffreys' on the number of images, with no Student
    factor (count = units; the slow reference: scipy's beta quantiles)."""
    n = 60
    res = te.evaluate(
        {"one": OneTarget(n)},
        {"bright": bright},
        scoring=te.Scoring(replicates=2000),
        progress=False,
    )
    row = res.summary.iloc[0]
    assert row.recall == 0.8
    m = n * t_shrink(n, 0.95, count=n)
    assert m == n
    x = 0.8 * m
    lo, hi = stats.beta.ppf([0.025, 0.975], x + 0.5, m - x + 0.5)
    width = hi - lo
    assert abs(row.recall_lo - lo) < 0.06 * width and abs(row.recall_hi - hi) < 0.06 * width


def _csv(runs) -> list[tuple[str, str]]:
    return [
        (summary_table({"chips": r}).to_csv(), paired_table({"chips": r}).to_csv()) for r in runs
    ]


def test_summary_and_paired_bytes_do_not_depend_on_the_shard_size(tmp_path):
    """The intervals come from states that add up: the same CSV bytes for one shard and
    for small shards."""
    runs = [
        run_shards(_job(9, 100), tmp_path / "a")[0],
        run_shards(_job(9, 2), tmp_path / "b")[0],
    ]
    a, b = _csv(runs)
    assert a == b


@pytest.mark.slow
def test_summary_and_paired_bytes_do_not_depend_on_the_workers(tmp_path):
    one = run_shards(_job(9, 2), tmp_path / "a")[0]
    two = run_shards(_on(_job(9, 2), workers=2), tmp_path / "b")[0]
    a, b = _csv([one, two])
    assert a == b
