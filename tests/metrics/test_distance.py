from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import distance_matrix

from tests.reference.distance import (
    brute_force_optimal,
    greedy_loop,
    nearest_distance_loop,
    xview3_true_positives,
)
from torchsar.errors import InputValueError, OptionError, ShapeError
from torchsar.metrics.distance import (
    LengthErrors,
    dont_care,
    greedy_match_by_score,
    length_score,
    optimal_match,
    pair_distances,
    parse_distance,
)

SPACINGS = [None, (0.5, 2.0), (2.0, 0.5), (10.0, 10.0), (1.0, 3.0)]


def _points(rng, n, size=9):
    """Integer grid points: equal distances and pairs exactly at the tolerance happen."""
    return rng.integers(0, size, size=(n, 2)).astype(np.float64)


def _check_valid(match, dist, tol):
    hit = match >= 0
    assert len(set(match[hit].tolist())) == hit.sum()  # one-to-one
    assert (dist[np.flatnonzero(hit), match[hit]] < tol).all()


# --- optimal ----------------------------------------------------------------------------


@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    d=st.integers(0, 6),
    g=st.integers(0, 6),
    tol=st.sampled_from([1.0, 2.0, 2.5, 3.0, 5.0]),
    spacing=st.sampled_from(SPACINGS),
)
def test_optimal_equals_brute_force(seed, d, g, tol, spacing):
    rng = np.random.default_rng(seed)
    dist = pair_distances(_points(rng, d), _points(rng, g), spacing)
    match = optimal_match(dist, tol)
    _check_valid(match, dist, tol)
    pairs, total = brute_force_optimal(dist, tol)
    hit = match >= 0
    assert hit.sum() == pairs
    assert math.isclose(dist[np.flatnonzero(hit), match[hit]].sum(), total, abs_tol=1e-9)


def test_metres_and_pixels_pick_different_nearest_points():
    """Spacing (0.5, 2.0): (4, 0) is 4 px but 2 m away, (0, 3) is 3 px but 6 m away."""
    det = np.array([[0.0, 0.0]])
    gt = np.array([[4.0, 0.0], [0.0, 3.0]])
    px = pair_distances(det, gt)
    m = pair_distances(det, gt, (0.5, 2.0))
    assert px.tolist() == [[4.0, 3.0]] and m.tolist() == [[2.0, 6.0]]
    assert optimal_match(px, 10.0).tolist() == [1]
    assert optimal_match(m, 10.0).tolist() == [0]
    assert greedy_match_by_score(px, np.ones(1), 10.0).tolist() == [1]
    assert greedy_match_by_score(m, np.ones(1), 10.0).tolist() == [0]
    # And a second detection that needs the metre-nearest point of the first one: optimal
    # reassigns, greedy (first detection first) cannot.
    det2 = np.array([[0.0, 0.0], [6.0, 0.0]])  # 1 m from (4, 0), 6.7 m from (0, 3)
    m2 = pair_distances(det2, gt, (0.5, 2.0))
    assert optimal_match(m2, 6.5).tolist() == [1, 0]
    assert greedy_match_by_score(m2, np.array([2.0, 1.0]), 6.5).tolist() == [0, -1]


def test_isotropic_spacing_reproduces_xview3_distances_bit_for_bit():
    rng = np.random.default_rng(0)
    det, gt = rng.uniform(0, 3000, (40, 2)), rng.uniform(0, 3000, (30, 2))
    assert np.array_equal(pair_distances(det, gt, (10.0, 10.0)), distance_matrix(det, gt) * 10)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), d=st.integers(0, 8), g=st.integers(0, 8))
def test_optimal_counts_as_xview3_when_no_distance_equals_the_tolerance(seed, d, g):
    rng = np.random.default_rng(seed)
    dist = pair_distances(rng.uniform(0, 60, (d, 2)), rng.uniform(0, 60, (g, 2)), (10.0, 10.0))
    assert not (dist == 200.0).any()
    assert (optimal_match(dist, 200.0) >= 0).sum() == xview3_true_positives(dist, 200.0)


def test_pair_at_the_tolerance_does_not_match_and_does_not_block():
    """A at 200 m (offset (12, 16) px at 10 m) of X and 10 m of Y; B at 200 m of Y. xView3's
    costly_dist keeps the two 200 m pairs in its assignment and then counts neither; here
    they are out of range, so A-Y is found."""
    det = np.array([[0.0, 0.0], [-12.0, -15.0]])
    gt = np.array([[12.0, 16.0], [0.0, 1.0]])
    dist = pair_distances(det, gt, (10.0, 10.0))
    assert dist[0, 0] == 200.0 and dist[1, 1] == 200.0 and dist[0, 1] == 10.0
    assert optimal_match(dist, 200.0).tolist() == [1, -1]
    assert xview3_true_positives(dist, 200.0) == 0
    assert optimal_match(np.array([[200.0]]), 200.0).tolist() == [-1]
    assert optimal_match(np.array([[199.99]]), 200.0).tolist() == [0]


# --- greedy -----------------------------------------------------------------------------


@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    d=st.integers(0, 9),
    g=st.integers(0, 7),
    tol=st.sampled_from([1.0, 2.0, 3.0, 5.0]),
    spacing=st.sampled_from(SPACINGS),
)
def test_greedy_equals_the_loop_with_score_and_distance_ties(seed, d, g, tol, spacing):
    rng = np.random.default_rng(seed)
    dist = pair_distances(_points(rng, d, 6), _points(rng, g, 6), spacing)
    score = rng.choice([0.1, 0.5, 0.5, 0.9, -np.inf], size=d)  # ties on purpose
    got = greedy_match_by_score(dist, score, tol)
    assert got.tolist() == greedy_loop(dist, score, tol).tolist()
    _check_valid(got, dist, tol)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), d=st.integers(1, 9), g=st.integers(0, 7))
def test_greedy_is_nested_by_score(seed, d, g):
    rng = np.random.default_rng(seed)
    dist = pair_distances(_points(rng, d, 6), _points(rng, g, 6))
    score = rng.choice([0.1, 0.5, 0.9], size=d)
    full = greedy_match_by_score(dist, score, 3.0)
    order = np.argsort(-score, kind="stable")
    for k in range(d + 1):
        top = order[:k]
        assert np.array_equal(greedy_match_by_score(dist[top], score[top], 3.0), full[top])


def test_greedy_ties_hand_computed():
    dist = np.array([[1.0, 1.0, 0.5], [1.0, 1.0, 9.0], [1.0, 1.0, 9.0]])
    score = np.array([0.5, 0.7, 0.7])
    # det 1 (first of the 0.7 tie) takes column 0 (lowest of the equal distances), det 2
    # column 1, det 0 its nearest column 2.
    assert greedy_match_by_score(dist, score, 2.0).tolist() == [2, 0, 1]


# --- don't care -------------------------------------------------------------------------


def test_dont_care_marks_only_unmatched_detections_strictly_within_the_tolerance():
    det = np.array([[0.0, 0.0], [0.0, 10.0], [0.0, 20.0], [0.0, 30.0], [0.0, 50.0]])
    gt = np.array([[0.0, 1.0]])
    low = np.array([[0.0, 0.0], [0.0, 33.0], [0.0, 25.0]])
    matched = optimal_match(pair_distances(det, gt), 4.0)
    assert matched.tolist() == [0, -1, -1, -1, -1]
    near = nearest_distance_loop(det, low)
    assert near.tolist() == [0.0, 10.0, 5.0, 3.0, 17.0]
    # det 0 is matched (a real match wins), det 2 is exactly at the tolerance (not ignored),
    # det 3 is within it; one don't-care point may absorb several detections.
    assert dont_care(det, matched, near, 5.0).tolist() == [False, False, False, True, False]
    assert dont_care(det, matched, near, 20.0).tolist() == [False, True, True, True, True]
    none = nearest_distance_loop(det, np.empty((0, 2)))
    assert not dont_care(det, matched, none, 1e9).any()


def test_dont_care_validates_its_arguments():
    det = np.zeros((2, 2))
    with pytest.raises(ShapeError, match="matched"):
        dont_care(det, np.array([-1]), np.zeros(2), 1.0)
    with pytest.raises(ShapeError, match="ignore_dist"):
        dont_care(det, np.array([-1, -1]), np.zeros(3), 1.0)
    with pytest.raises(InputValueError, match="ignore_dist"):
        dont_care(det, np.array([-1, -1]), np.array([np.nan, 1.0]), 1.0)
    with pytest.raises(InputValueError, match="matched"):
        dont_care(det, np.array([-1.0, 0.5]), np.zeros(2), 1.0)
    with pytest.raises(OptionError, match="max_distance"):
        dont_care(det, np.array([-1, -1]), np.zeros(2), 0.0)


# --- length -----------------------------------------------------------------------------


def test_length_score_hand_computed():
    # |110-100|/100 = 0.1, |90-100|/100 = 0.1, |min(600,500)-400|/400 = 0.25 (the cap), one
    # unknown true and one unknown predicted length skipped: 1 - 0.45 / 3 = 0.85.
    pred = np.array([110.0, 90.0, 600.0, 50.0, np.nan])
    true = np.array([100.0, 100.0, 400.0, np.nan, 30.0])
    assert length_score(pred, true) == pytest.approx(0.85, abs=1e-12)
    # Both capped: 700 vs 800 is no error.
    assert length_score(np.array([700.0]), np.array([800.0])) == 1.0
    # Mean relative error above 1 scores 0.
    assert length_score(np.array([10.0, 0.0]), np.array([2.0, 5.0])) == 0.0
    assert math.isnan(length_score(np.array([np.nan]), np.array([20.0])))
    assert math.isnan(length_score(np.empty(0), np.empty(0)))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(0, 30), cuts=st.lists(st.integers(0, 30)))
def test_length_errors_merge_exactly_in_any_split_and_order(seed, n, cuts):
    rng = np.random.default_rng(seed)
    pred = rng.uniform(0, 700, n)
    true = rng.uniform(1, 600, n)
    pred[rng.random(n) < 0.2] = np.nan
    true[rng.random(n) < 0.2] = np.nan
    one_pass = LengthErrors().add(pred, true)
    bounds = [0, *sorted(min(c, n) for c in cuts), n]
    parts = [LengthErrors().add(pred[a:b], true[a:b]) for a, b in itertools.pairwise(bounds)]
    merged = LengthErrors()
    for k in rng.permutation(len(parts)):
        merged = merged + parts[k]
    assert merged == one_pass
    assert one_pass.count == int((~np.isnan(pred) & ~np.isnan(true)).sum())
    if one_pass.count:
        p, t = np.minimum(pred, 500), np.minimum(true, 500)
        mean = np.nanmean(np.abs(p - t) / t)
        assert one_pass.score == pytest.approx(1 - min(mean, 1), abs=1e-9)
        assert length_score(pred, true) == one_pass.score


def test_length_inputs_are_validated():
    with pytest.raises(InputValueError, match="true_m"):
        length_score(np.array([1.0]), np.array([0.0]))
    with pytest.raises(InputValueError, match="pred_m"):
        length_score(np.array([-1.0]), np.array([3.0]))
    with pytest.raises(ShapeError, match="true_m"):
        length_score(np.array([1.0, 2.0]), np.array([3.0]))
    assert LengthErrors().__add__(3) is NotImplemented


# --- parser -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("200m", (200.0, "m")),
        ("200 m", (200.0, "m")),
        (" 12.5m ", (12.5, "m")),
        ("20px", (20.0, "px")),
        ("20 px", (20.0, "px")),
        ("20", (20.0, "px")),
        ("1e3m", (1000.0, "m")),
        (".5", (0.5, "px")),
    ],
)
def test_parse_distance_accepts(text, expected):
    assert parse_distance(text) == expected


@pytest.mark.parametrize(
    "text",
    [
        "-200m",
        "0",
        "0px",
        "nan",
        "NaN m",
        "inf",
        "infm",
        "-inf px",
        "200km",
        "20 pixels",
        "m",
        "",
        "200 m m",
        "2 00m",
        None,
        200,
    ],
)
def test_parse_distance_refuses(text):
    with pytest.raises(OptionError, match="max_distance"):
        parse_distance(text)


# --- empty inputs and validation --------------------------------------------------------


@pytest.mark.parametrize(("d", "g"), [(0, 0), (0, 3), (3, 0)])
def test_empty_inputs_are_valid(d, g):
    det, gt = np.zeros((d, 2)), np.ones((g, 2))
    for spacing in (None, (0.5, 2.0)):
        dist = pair_distances(det, gt, spacing)
        assert dist.shape == (d, g)
        assert optimal_match(dist, 5.0).tolist() == [-1] * d
        assert greedy_match_by_score(dist, np.zeros(d), 5.0).tolist() == [-1] * d
        assert dont_care(det, np.full(d, -1), np.full(d, np.inf), 5.0).tolist() == [False] * d
    assert pair_distances(np.empty(0), np.empty(0)).shape == (0, 0)


@pytest.mark.parametrize("bad", [0, -1.0, math.nan, math.inf, True, "200m", None])
def test_max_distance_is_validated(bad):
    dist = np.ones((2, 2))
    with pytest.raises(OptionError, match="max_distance"):
        optimal_match(dist, bad)
    with pytest.raises(OptionError, match="max_distance"):
        greedy_match_by_score(dist, np.zeros(2), bad)


def test_arrays_are_validated():
    with pytest.raises(ShapeError, match="det"):
        pair_distances(np.zeros((2, 3)), np.zeros((1, 2)))
    with pytest.raises(InputValueError, match="gt"):
        pair_distances(np.zeros((2, 2)), np.array([[np.nan, 1.0]]))
    for spacing in [(0.0, 1.0), (1.0,), (1.0, math.inf), (True, 1.0), "10m"]:
        with pytest.raises(OptionError, match="spacing"):
            pair_distances(np.zeros((1, 2)), np.zeros((1, 2)), spacing)
    with pytest.raises(InputValueError, match="dist"):
        optimal_match(np.array([[np.nan]]), 1.0)
    with pytest.raises(InputValueError, match="dist"):
        optimal_match(np.array([[-1.0]]), 1.0)
    with pytest.raises(ShapeError, match="dist"):
        optimal_match(np.ones(3), 1.0)
    with pytest.raises(ShapeError, match="score"):
        greedy_match_by_score(np.ones((2, 1)), np.ones(3), 1.0)
    with pytest.raises(InputValueError, match="score"):
        greedy_match_by_score(np.ones((1, 1)), np.array([np.nan]), 1.0)
    # inf distances are valid and never match
    assert optimal_match(np.array([[np.inf, 1.0]]), 2.0).tolist() == [1]
