"""The discrimination stage's two paths: the numba kernels (closing and labelling on the set
pixels only) and the numpy / scikit-image path give the same pixels, labels and objects, and
both equal the slow references (scipy closing and labelling)."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.objects.test_components import _reference as reference_labels
from tests.objects.test_discriminate import _reference_closing
from torchsar import _jit
from torchsar.objects import ObjectRules, Objects, discriminate, normalised_score
from torchsar.objects.closing import close_pixels
from torchsar.objects.components import label_pixels
from torchsar.objects.discriminate import own_regions

PATHS = ["numpy"] + (["numba"] if importlib.util.find_spec("numba") else [])


@pytest.fixture(scope="module", params=PATHS)
def path(request):
    """Run the test with the compiled kernels on (``numba``) or off (``numpy``)."""
    old = _jit.ENABLED
    _jit.ENABLED = request.param == "numba"
    yield request.param
    _jit.ENABLED = old


def _mask(seed: int, shape: tuple[int, int, int], density: float) -> np.ndarray:
    return np.random.default_rng(seed).random(shape) < density


SHAPES = st.sampled_from([(1, 1, 1), (2, 7, 9), (3, 1, 12), (2, 12, 1), (1, 16, 16)])


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000), shape=SHAPES, density=st.floats(0.0, 0.7), radius=st.integers(0, 4)
)
def test_closing_equals_scipy(path, seed, shape, density, radius):
    mask = _mask(seed, shape, density)
    got = close_pixels(np.flatnonzero(mask), shape, radius)
    want = np.stack([_reference_closing(m, radius) for m in mask]) if radius else mask
    assert got.dtype == np.int64 or got.size == 0
    assert np.array_equal(got, np.flatnonzero(want))


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    shape=SHAPES,
    density=st.floats(0.0, 0.9),
    connectivity=st.sampled_from([1, 2]),
)
def test_labels_equal_scipy(path, seed, shape, density, connectivity):
    mask = _mask(seed, shape, density)
    idx = np.flatnonzero(mask)
    labels, n, lab = label_pixels(idx, shape, connectivity)
    ref, n_ref = reference_labels(mask, connectivity)
    assert n == n_ref and labels.dtype == np.int32 and np.array_equal(labels, ref)
    assert np.array_equal(lab, ref.reshape(-1)[idx])


def _objects(seed: int, rules: ObjectRules) -> Objects:
    rng = np.random.default_rng(seed)
    stat = rng.gamma(1.0, 1.0, (3, 2, 20, 24)) * np.where(rng.random((3, 2, 20, 24)) < 0.1, 8, 1)
    return discriminate(torch.as_tensor(stat), 3.0, rules=rules)


def _fields(obj: Objects) -> list[np.ndarray]:
    return [
        obj.labels,
        obj.plane,
        obj.score,
        obj.area,
        obj.box,
        obj.centroid,
        obj.length,
        obj.width,
    ]


@pytest.mark.parametrize(
    "rules",
    [
        ObjectRules(),
        ObjectRules(closing=2, min_area=5),
        ObjectRules(closing=1, connectivity=4, max_area=30),
        ObjectRules(floor=0.5, closing=3),
    ],
)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_discriminate_same_objects_on_both_paths(rules, seed):
    old = _jit.ENABLED
    try:
        _jit.ENABLED = False
        slow = _objects(seed, rules)
        _jit.ENABLED = bool(PATHS[1:])
        fast = _objects(seed, rules)
    finally:
        _jit.ENABLED = old
    for a, b in zip(_fields(slow), _fields(fast), strict=True):
        assert a.dtype == b.dtype and np.array_equal(a, b)  # bit for bit


def test_known_pixel_lists_are_the_label_maps(path):
    obj = _objects(5, ObjectRules(closing=2, min_area=5))
    owner, idx = obj.pixel_lists()
    flat = obj.labels.reshape(-1)
    assert np.array_equal(idx, np.flatnonzero(flat))
    assert owner.dtype == np.int64 and np.array_equal(owner, flat[idx] - 1)
    lab = np.zeros((2, 5, 6), np.int64)
    lab[0, 1:3, 1:4], lab[1, 0, 0], lab[1, 4, 5] = 9, 4, -3  # ids need not be consecutive
    made = Objects.from_labels(lab, np.ones(lab.shape))
    owner, idx = made.pixel_lists()
    assert np.array_equal(idx, np.flatnonzero(made.labels)) and owner.tolist() == [0] * 6 + [1]


@pytest.mark.parametrize("threshold", [2.0, -0.5, "per image"])
def test_own_regions_equal_labels_scored_on_the_whole_map(threshold):
    rng = np.random.default_rng(3)
    stat = torch.as_tensor(rng.gamma(1.0, 2.0, (2, 2, 9, 11)))
    labels = torch.as_tensor(rng.integers(0, 4, (2, 2, 9, 11)) * (rng.random((2, 2, 9, 11)) < 0.3))
    thr = torch.tensor([1.5, 3.0]).reshape(2, 1, 1, 1) if threshold == "per image" else threshold
    got = own_regions(stat, thr, labels)
    want = Objects.from_labels(
        labels.reshape(4, 9, 11).numpy(), normalised_score(stat, thr).reshape(4, 9, 11).numpy()
    )
    for a, b in zip(_fields(want), _fields(got), strict=True):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    assert np.array_equal(got.pixel_lists()[1], np.flatnonzero(got.labels))


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("ordered", [True, False])
def test_measurements_same_on_both_paths(monkeypatch, seed, ordered):
    """One pass of the kernel against numpy's reductions: unsorted ids, pixels owned twice,
    ids without pixels, ties of 0.0 and -0.0, scores of -inf; bit for bit."""
    from tests.kernel_paths import both
    from torchsar.objects.properties import measure_pixels

    rng = np.random.default_rng(seed)
    shape, n = (3, 17, 23), 9
    m = int(rng.integers(0, 300))
    idx = np.sort(rng.integers(0, np.prod(shape), m))
    lab = rng.integers(1, n, m)  # id n has no pixel
    if ordered:
        lab = np.sort(lab)
    values = rng.choice([0.0, -0.0, -np.inf, 2.5, 7.0], m) * rng.choice([1.0, 0.5], m)
    fast, slow = both(monkeypatch, lambda: measure_pixels(lab, idx, shape[1:], n, values))
    assert fast.keys() == slow.keys()
    for key in fast:
        a, b = fast[key], slow[key]
        assert a.dtype == b.dtype and a.shape == b.shape, key
        assert np.array_equal(a, b) and np.array_equal(np.signbit(a), np.signbit(b)), key
    for k in range(1, n + 1):  # against the pixels themselves
        own = idx[lab == k]
        rows, cols = (own // shape[2]) % shape[1], own % shape[2]
        assert fast["area"][k - 1] == own.size
        if own.size:
            assert fast["plane"][k - 1] == (own // (shape[1] * shape[2])).min()
            box = [rows.min(), cols.min(), rows.max() + 1, cols.max() + 1]
            assert fast["box"][k - 1].tolist() == box
            assert np.allclose(fast["centroid"][k - 1], [rows.mean(), cols.mean()])
            assert fast["score"][k - 1] == values[lab == k].max()


@pytest.mark.skipif(not PATHS[1:], reason="numba is not installed")
@pytest.mark.parametrize("seed", range(4))
def test_coordinates_walked_equal_divided(seed):
    """The kernels' plane / row / column of flat indices, walked along ascending runs,
    against division: runs, steps back, jumps across planes, one-pixel rows and columns."""
    from torchsar.objects._kernels import _coords

    rng = np.random.default_rng(seed)
    for shape in [(4, 9, 11), (3, 1, 7), (2, 6, 1), (5, 2, 2)]:
        size = int(np.prod(shape))
        parts = [np.sort(rng.integers(0, size, 40)), rng.integers(0, size, 15), np.arange(size)]
        idx = np.concatenate(parts).astype(np.int64)
        got = _coords(idx, shape[1], shape[2])
        want = np.stack(np.unravel_index(idx, shape))
        assert np.array_equal(got, want)
