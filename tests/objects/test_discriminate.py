from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage
from skimage.measure import label, regionprops
from skimage.morphology import disk

from torchsar.errors import InputTypeError, InputValueError, OptionError, ShapeError
from torchsar.objects import ObjectRules, discriminate, normalised_score


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), density=st.floats(0.02, 0.5), conn=st.sampled_from([4, 8]))
def test_objects_match_skimage_regionprops(seed, density, conn):
    rng = np.random.default_rng(seed)
    stat = rng.random((2, 1, 12, 15)) * (rng.random((2, 1, 12, 15)) < density) * 10
    obj = discriminate(torch.as_tensor(stat), 0.5, rules=ObjectRules(connectivity=conn))
    k = 0
    for p in range(2):
        lab = label(stat[p, 0] > 0.5, connectivity=2 if conn == 8 else 1)
        for r in regionprops(lab, intensity_image=stat[p, 0] / 0.5):
            assert obj.plane[k] == p and obj.area[k] == r.area
            assert obj.box[k].tolist() == list(r.bbox)
            np.testing.assert_allclose(obj.centroid[k], r.centroid, atol=1e-9)
            np.testing.assert_allclose(
                [obj.length[k], obj.width[k]], [r.axis_major_length, r.axis_minor_length], atol=1e-6
            )
            assert obj.score[k] == pytest.approx(r.intensity_max)
            assert np.array_equal(obj.labels[p] == k + 1, lab == r.label)
            k += 1
    assert k == len(obj)


def _reference_closing(mask: np.ndarray, radius: int) -> np.ndarray:
    """Closing by a disk with scipy: dilation with the outside unset, erosion with the
    outside set (so nothing is eroded from the border), the mask itself kept."""
    fp = disk(radius).astype(bool)
    grown = ndimage.binary_dilation(np.pad(mask, radius), fp)
    closed = ndimage.binary_erosion(grown, fp, border_value=1)[radius:-radius, radius:-radius]
    return closed | mask


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), density=st.floats(0.01, 0.4), radius=st.integers(1, 4))
def test_closing_equals_scipy_reference(seed, density, radius):
    rng = np.random.default_rng(seed)
    stat = (rng.random((3, 1, 14, 17)) < density) * 5.0
    obj = discriminate(torch.as_tensor(stat), 1.0, rules=ObjectRules(closing=radius, min_area=1))
    for p in range(3):
        assert np.array_equal(obj.labels[p] > 0, _reference_closing(stat[p, 0] > 1, radius))


def test_closing_is_extensive_and_joins_fragments():
    stat = torch.zeros(1, 1, 20, 20)
    stat[0, 0, 5:10, 5:8] = 3.0
    stat[0, 0, 5:10, 10:13] = 3.0  # two pixels apart
    open_ = discriminate(stat, 1.0)
    closed = discriminate(stat, 1.0, rules=ObjectRules(closing=2))
    assert len(open_) == 2 and len(closed) == 1
    assert closed.area[0] >= open_.area.sum()
    assert bool(((open_.labels > 0) <= (closed.labels > 0)).all())  # nothing removed
    edge = torch.zeros(1, 1, 10, 10)
    edge[0, 0, 0, :] = 2.0  # a line on the border survives closing unchanged in extent
    assert discriminate(edge, 1.0, rules=ObjectRules(closing=3)).area[0] >= 10


def test_size_rules_in_pixels_and_square_metres():
    stat = torch.zeros(2, 1, 16, 16)
    stat[:, 0, 1:3, 1:3] = 2.0  # 4 px
    stat[:, 0, 8:14, 8:14] = 2.0  # 36 px
    assert discriminate(stat, 1.0, rules=ObjectRules(min_area=5)).area.tolist() == [36, 36]
    assert discriminate(stat, 1.0, rules=ObjectRules(max_area=10)).area.tolist() == [4, 4]
    m2 = ObjectRules(min_area=10.0, units="m2")  # plane 0: 1 m2/px; plane 1: 4 m2/px
    got = discriminate(stat, 1.0, rules=m2, pixel_area=np.array([1.0, 4.0]))
    assert got.plane.tolist() == [0, 1, 1] and got.area.tolist() == [36, 4, 36]
    with pytest.raises(OptionError, match="pixel_area"):
        discriminate(stat, 1.0, rules=m2)


def test_floor_and_score_normalisation():
    stat = torch.zeros(1, 1, 8, 8, dtype=torch.float64)
    stat[0, 0, 2, 2] = 6.0
    stat[0, 0, 2, 3] = 3.0  # below threshold 4 but above floor 0.5
    assert discriminate(stat, 4.0).area.tolist() == [1]
    low = discriminate(stat, 4.0, rules=ObjectRules(floor=0.5))
    assert low.area.tolist() == [2] and low.score.tolist() == [1.5]
    z = normalised_score(torch.tensor([-1.0, 0.5]), torch.tensor(-0.5))
    assert z.tolist() == [0.5, 2.0]  # non-positive threshold: 1 + s - t


def test_batch_invariance_empty_batch_and_errors():
    g = torch.Generator().manual_seed(0)
    stat = torch.rand(3, 1, 16, 16, generator=g) * 3
    whole = discriminate(stat, 2.0)
    parts = [discriminate(stat[i : i + 1], 2.0) for i in range(3)]
    assert whole.area.tolist() == np.concatenate([p.area for p in parts]).tolist()
    assert whole.score.tolist() == np.concatenate([p.score for p in parts]).tolist()
    assert len(discriminate(torch.zeros(0, 1, 8, 8), 1.0)) == 0
    full = discriminate(torch.full((1, 1, 8, 8), 5.0), 1.0)
    assert len(full) == 1 and full.area[0] == 64  # a flood is one object
    with pytest.raises(InputValueError):
        discriminate(torch.full((1, 1, 4, 4), float("nan")), 1.0)
    with pytest.raises(ShapeError):
        discriminate(torch.zeros(4, 4), 1.0)
    with pytest.raises(InputTypeError):
        discriminate(torch.zeros(1, 1, 4, 4, dtype=torch.int32), 1.0)
    for bad in (
        {"closing": -1},
        {"connectivity": 6},
        {"floor": 0},
        {"min_area": 5, "max_area": 2},
        {"units": "acres"},
    ):
        with pytest.raises(OptionError):
            ObjectRules(**bad)


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    thr=st.sampled_from([0.5, 3.0, 1e-9, 0.0, -2.0]),
    closing=st.sampled_from([0, 1]),
)
def test_statistic_scale_keeps_the_objects_and_scores_their_peak(seed, thr, closing):
    """``scale="statistic"``: the same objects as the ratio scale, each scored by the peak
    of the statistic over its own pixels (a slow reference per object), operating
    threshold the design threshold; the two scales rank the objects alike."""
    rng = np.random.default_rng(seed)
    stat = torch.as_tensor(rng.normal(size=(2, 1, 14, 13)) * 3 + thr)
    rules = ObjectRules(closing=closing, min_area=1, floor=0.5)
    ratio = discriminate(stat, thr, rules=rules)
    own = discriminate(stat, thr, rules=rules, scale="statistic")
    assert own.threshold == thr and ratio.threshold == 1.0
    assert np.array_equal(own.labels, ratio.labels) and np.array_equal(own.area, ratio.area)
    for k in range(len(own)):
        pixels = own.labels[own.plane[k]] == k + 1
        inside = stat[own.plane[k], 0].numpy()[pixels]
        ratio_px = normalised_score(torch.as_tensor(inside), thr).numpy()
        # closing-added pixels below the floor carry no score in either scale
        scored = ratio_px > rules.floor
        assert own.score[k] == inside[scored].max()
    # a strictly increasing map of each other: the same order, ties included
    assert np.array_equal(
        np.argsort(-own.score, kind="stable"), np.argsort(-ratio.score, kind="stable")
    )


def test_statistic_scale_needs_one_threshold():
    stat = torch.rand(2, 1, 8, 8)
    per_image = torch.tensor([0.5, 0.6]).reshape(2, 1, 1, 1)
    with pytest.raises(OptionError, match="one finite threshold"):
        discriminate(stat, per_image, scale="statistic")
    with pytest.raises(OptionError, match="scale"):
        discriminate(stat, 0.5, scale="probability")
    same = torch.full((2, 1, 1, 1), 0.5)  # every entry equal: one threshold
    assert discriminate(stat, same, scale="statistic").threshold == 0.5
