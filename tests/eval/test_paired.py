"""Paired comparison of detectors: a detector against itself is exactly 0, detectors that
differ by construction differ significantly, the bootstrap resamples images or groups, and
the new tables do not depend on the shard size."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch

import torchsar_eval as te
from torchsar.detection import detection_from
from torchsar.metrics.bootstrap import poisson_weights, unit_hash
from torchsar.metrics.paired import PAIRED_METRICS, paired_differences
from torchsar_eval.cli import build_parser
from torchsar_eval.commands.run.options import scoring_from
from torchsar_eval.errors import EvalError

SIZE = 48


class Squares(torch.utils.data.Dataset):
    """Two 5 x 5 targets per image on a dark background, one bright (intensity 300) and
    one dim (100); images ``4k .. 4k + 3`` form scene ``k`` (``meta["group"]``)."""

    def __init__(self, n: int) -> None:
        self.n = n

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, i: int) -> dict:
        rng = np.random.default_rng(i)
        image = torch.ones(1, SIZE, SIZE)
        inst = torch.zeros(1, SIZE, SIZE, dtype=torch.int32)
        r = int(rng.integers(2, 16))
        inst[0, r : r + 5, 4:9] = 1
        inst[0, 30:35, r + 20 : r + 25] = 2
        image[inst == 1], image[inst == 2] = 300.0, 100.0
        return {
            "image": image,
            "mask": inst > 0,
            "instances": inst,
            "ignore": torch.zeros(1, SIZE, SIZE, dtype=torch.bool),
            "meta": {"name": f"sq/{i}", "group": f"scene{i // 4}"},
        }


def every_target(x):
    """Finds both targets."""
    return detection_from(x / 50.0, 1.0)


def bright_only(x):
    """Finds the bright targets only: a strict subset of :func:`every_target`'s."""
    return detection_from(x / 200.0, 1.0)


def with_false_alarms(x):
    """:func:`every_target` plus two bright false alarms in every image."""
    stat = x / 50.0
    stat[..., 42:45, 2:5] = 5.0
    stat[..., 42:45, 40:43] = 5.0
    return detection_from(stat, 1.0)


DETECTORS = {"all": every_target, "bright": bright_only, "fa": with_false_alarms}


def _run(n=24, shard_size=256, unit="image", replicates=200):
    scoring = te.Scoring(replicates=replicates, bootstrap_unit=unit)
    return te.evaluate(
        {"sq": Squares(n)},
        DETECTORS,
        scoring=scoring,
        execution=te.Execution(shard_size=shard_size),
        progress=False,
    )


@pytest.fixture(scope="module")
def results():
    return _run()


def test_a_detector_against_itself_is_exactly_zero(results):
    for r in results.states["sq"]:
        for metric, (d, lo, hi) in paired_differences(
            r.objects, r.objects, r.threshold, r.threshold
        ).items():
            assert (d, lo, hi) == (0.0, 0.0, 0.0), metric


def test_detectors_that_differ_by_construction_differ_significantly(results):
    p = results.paired.set_index(["detector", "metric"])
    assert set(results.paired.reference) == {"all"}  # the best F1: every target, no false alarm
    assert set(results.paired.detector) == {"bright", "fa"}
    assert list(results.paired.columns) == [
        "dataset",
        "detector",
        "reference",
        "metric",
        "difference",
        "lo",
        "hi",
        "significant",
    ]
    bright = p.loc["bright"]
    assert bright.loc["recall", "difference"] == pytest.approx(-0.5)
    assert bright.loc["recall", "hi"] < 0 and bright.loc["recall", "significant"]
    fa = p.loc["fa"]
    assert fa.loc["f1", "difference"] < 0 and fa.loc["f1", "hi"] < 0 and fa.loc["f1", "significant"]
    # the same targets found: no recall difference in any replicate
    assert tuple(fa.loc["recall", ["difference", "lo", "hi"]]) == (0.0, 0.0, 0.0)
    assert not fa.loc["recall", "significant"]
    for metric in PAIRED_METRICS:
        row = p.loc[("fa", metric)]
        assert row.lo <= row.difference <= row.hi or row.lo == row.hi
        assert row.lo < row.hi or row.difference == row.lo == row.hi == 0.0


def test_the_paired_interval_recovers_the_two_intervals_and_their_correlation(results):
    """Against a direct reading of the two states: each one's own interval and the
    correlation of their replicates, combined by square-and-add (Zou & Donner)."""
    ref, fa = results.states["sq"][0], results.states["sq"][2]
    a = fa.objects.replicate_metrics(fa.threshold)
    b = ref.objects.replicate_metrics(ref.threshold)
    ia, ib = fa.objects.intervals(fa.threshold)["f1"], ref.objects.intervals(ref.threshold)["f1"]
    ok = np.isfinite(a["f1"]) & np.isfinite(b["f1"])
    r = np.corrcoef(a["f1"][ok], b["f1"][ok])[0, 1] if b["f1"][ok].std() > 0 else 0.0
    pa, pb = ia.centre, ib.centre
    lo = (pa - pb) - np.sqrt(
        (pa - ia.lo) ** 2 + (ib.hi - pb) ** 2 - 2 * r * (pa - ia.lo) * (ib.hi - pb)
    )
    hi = (pa - pb) + np.sqrt(
        (ia.hi - pa) ** 2 + (pb - ib.lo) ** 2 - 2 * r * (ia.hi - pa) * (pb - ib.lo)
    )
    row = results.paired.set_index(["detector", "metric"]).loc[("fa", "f1")]
    d = row.difference  # the interval is widened to its point when the centres moved past it
    assert (row.lo, row.hi) == pytest.approx((min(lo, d), max(hi, d)))


@pytest.mark.parametrize("unit", ["image", "group"])
def test_new_tables_do_not_depend_on_the_shard_size(unit):
    a, b = _run(12, 2, unit, 50), _run(12, 256, unit, 50)
    for name in ("scr", "errors", "paired", "breakdown", "summary"):
        pd.testing.assert_frame_equal(getattr(a, name), getattr(b, name))


def test_group_unit_resamples_whole_scenes():
    """With ``bootstrap_unit="group"`` every image of a scene gets its scene's weights: the
    replicate target counts are the scenes' counts weighted by the scenes' Poisson weights."""
    res = _run(12, 256, "group", 50)
    state = res.states["sq"][0].objects
    assert state.units == 3
    units = np.array([unit_hash(f"group:scene{k}") for k in range(3)], np.uint64)
    res_ = state.resampled()
    np.testing.assert_array_equal(np.sort(units), res_.units)
    np.testing.assert_array_equal(res_.unit_gt, np.full(3, 8))  # 4 images x 2 targets
    np.testing.assert_array_equal(res_.unit_images, np.full(3, 4))
    # the replicates count each scene's 4 images as often as its group's weight draws
    w = poisson_weights(units[np.argsort(units)], 50, seed=0).astype(float)
    fa = state.replicate_metrics()["fa_per_image"]  # every_target: no false alarm
    np.testing.assert_array_equal(fa, np.where(w.sum(axis=1) > 0, 0.0, np.nan))
    image_unit = _run(12, 256, "image", 50).states["sq"][0].objects
    assert image_unit.units == 12


def test_bootstrap_unit_option_and_flag():
    with pytest.raises(EvalError, match="bootstrap_unit.*'scene'"):
        te.Scoring(bootstrap_unit="scene")
    parser = build_parser()
    args = parser.parse_args(["run", "--bootstrap-unit", "group"])
    assert scoring_from(args).bootstrap_unit == "group"
    assert scoring_from(parser.parse_args(["run"])).bootstrap_unit == "image"
    with pytest.raises(SystemExit):
        parser.parse_args(["run", "--bootstrap-unit", "scene"])
    assert te.Scoring(bootstrap_unit="group").as_dict()["bootstrap"]["unit"] == "group"
