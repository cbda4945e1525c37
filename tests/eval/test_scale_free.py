"""Scale-free tables from the public route: a detector and a strictly increasing map of its
scores (its threshold mapped too) give identical tables (score columns mapped), a paired
difference of exactly 0 that is not significant, the mapped calibrated threshold; every
printed interval contains its point; clutter squares given as boxes and as masks score the
same false alarms."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import torchsar as ts
import torchsar_eval as te
from torchsar.objects import Objects

MAPS = {
    "sharpen": lambda s: 1.0 - 1e-12 * (2.0 - s),  # within 1e-12 of 1
    "stretch": lambda s: 10.0 ** (8.0 * s),  # past 1e6
    "affine": lambda s: 3.0 * s - 10.0,  # negative numbers
}
"""Strictly increasing maps of scores in (0, 2) that keep 1/64 steps distinct in float64."""


class Boxes:
    """Boxes around each chip's bright pixels plus a few in the clutter, scored on a grid of
    1/64 steps in (0, 2) (ties across images included), mapped by ``f``."""

    def __init__(self, f=lambda s: s, threshold: float = 1.0) -> None:
        self.f, self.threshold = f, threshold

    def __call__(self, images, meta) -> Objects:
        boxes, scores, planes = [], [], []
        for k, (x, m) in enumerate(zip(images[:, 0].numpy(), meta, strict=True)):
            rng = np.random.default_rng(int(m["index"]))
            r, c = np.unravel_index(int(np.argmax(x)), x.shape)
            for dr, dc in [(0, 0), *rng.integers(-40, 40, (int(rng.integers(1, 5)), 2))]:
                r0, c0 = int(np.clip(r + dr - 6, 0, 100)), int(np.clip(c + dc - 6, 0, 100))
                boxes.append([r0, c0, r0 + 12, c0 + 12])
                scores.append(int(rng.integers(1, 128)) / 64.0)
                planes.append(k)
        return Objects.from_boxes(
            np.array(boxes, float).reshape(-1, 4),
            self.f(np.array(scores)),
            shape=images.shape[-2:],
            plane=np.array(planes),
            planes=len(meta),
            threshold=float(self.f(np.float64(self.threshold))),
        )


SCORE_COLUMNS = {
    "froc": "threshold",
    "pr": "threshold",
    "summary": "score_threshold",
    "per_image": "max_score",
}


def _run(f, **kw):
    scoring = te.Scoring(replicates=60)
    dets = {"a": te.Detector("a", Boxes()), "b": te.Detector("b", Boxes(f))}
    return te.evaluate({"chips": "sim-chips"}, dets, n=24, scoring=scoring, progress=False, **kw)


def _rows(df: pd.DataFrame, det: str) -> pd.DataFrame:
    return df[df.detector == det].drop(columns="detector").reset_index(drop=True)


@settings(max_examples=3, deadline=None)
@given(name=st.sampled_from(sorted(MAPS)))
def test_a_monotone_map_of_the_scores_changes_no_number(name):
    f = MAPS[name]
    res = _run(f)
    for table in ("summary", "froc", "pr", "breakdown", "errors", "scr", "per_image"):
        a, b = _rows(getattr(res, table), "a"), _rows(getattr(res, table), "b")
        col = SCORE_COLUMNS.get(table)
        if col is not None:
            np.testing.assert_array_equal(f(a[col].to_numpy(float)), b[col].to_numpy(float))
            a, b = a.drop(columns=col), b.drop(columns=col)
        pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=0, atol=1e-12, obj=table)
    paired = res.paired
    assert len(paired) and (paired[["difference", "lo", "hi"]].to_numpy() == 0).all()
    assert not paired.significant.any()


def test_calibrated_operating_points_map_with_the_scores():
    f = MAPS["stretch"]
    res = _run(f, calibration=te.Calibration(target="fa=0.5"))
    s = res.summary.set_index("detector")
    assert f(s.loc["a", "score_threshold"]) == s.loc["b", "score_threshold"]
    cols = [c for c in s.columns if c not in ("score_threshold", "dataset")]
    pd.testing.assert_series_equal(s.loc["a", cols], s.loc["b", cols], check_names=False)


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 1000), n=st.integers(3, 12))
def test_every_printed_interval_contains_its_point(seed, n):
    res = te.evaluate(
        {"chips": "sim-chips"},
        {"a": te.Detector("a", Boxes()), "ca": "ca"},
        n=n,
        seed=seed,
        scoring=te.Scoring(replicates=40),
        progress=False,
    )
    s = res.summary
    for col in [c[:-3] for c in s.columns if c.endswith("_lo")]:
        lo, hi, v = s[f"{col}_lo"], s[f"{col}_hi"], s[col]
        ok = lo.isna() | hi.isna() | ((lo <= v + 1e-12) & (v <= hi + 1e-12))
        assert ok.all(), (col, s[[col, f"{col}_lo", f"{col}_hi"]])
    p = res.paired
    assert ((p.lo <= p.difference + 1e-12) & (p.difference <= p.hi + 1e-12) | p.lo.isna()).all()


class Squares:
    """8 x 8 squares at fixed places of each scene, as boxes or as masks."""

    def __init__(self, masks: bool) -> None:
        self.masks = masks

    def __call__(self, images) -> Objects:
        b, _, h, w = images.shape
        grid = [(r, c) for r in range(4, h - 12, 24) for c in range(4, w - 12, 24)]
        box = np.array([[r, c, r + 8, c + 8] for r, c in grid] * b, float)
        plane = np.repeat(np.arange(b), len(grid))
        score = np.linspace(0.1, 0.9, box.shape[0])
        if not self.masks:
            return Objects.from_boxes(box, score, shape=(h, w), plane=plane, planes=b)
        m = np.zeros((box.shape[0], h, w), bool)
        for k, (r0, c0, r1, c1) in enumerate(box.astype(int)):
            m[k, r0:r1, c0:c1] = True
        return Objects.from_masks(m, score, plane=plane, planes=b)


@pytest.mark.parametrize("kind", ["centroid", "box"])
def test_clutter_squares_as_boxes_and_as_masks_score_the_same(kind):
    """A box that lies on no ignore pixel is never ignored: the same squares given as boxes
    and as masks on simulated scenes (with shadows as ignore pixels) score the same."""
    scoring = te.Scoring(matching=te.Matching(kind=kind), replicates=0)
    res = te.evaluate(
        {"scenes": "sim-scenes"},
        {"boxes": Squares(False), "masks": Squares(True)},
        n=2,
        scoring=scoring,
        progress=False,
    ).summary.set_index("detector")
    assert res.loc["boxes", "fp"] == res.loc["masks", "fp"] > 100
    assert res.loc["boxes", "tp"] == res.loc["masks", "tp"]
    scenes = ts.simulate.scenes(2, seed=0)
    assert scenes.ignore.any()  # there were ignore pixels to be (wrongly) under a box
