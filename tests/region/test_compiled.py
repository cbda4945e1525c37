"""The compiled region kernels (numba) equal the Python path bit for bit, and the slow
references: growth, numpy's summation, connected components, holes, objects, labels, and
the whole detector on many seeded chips and scenes under every option that changes a path."""

from __future__ import annotations

import importlib
import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

import torchsar as ts
from tests.reference import region as ref
from tests.region.test_steps import _painted, _state
from torchsar import _jit
from torchsar.region import region_search
from torchsar.region.grow import Grid, grow
from torchsar.region.seeds import local_maxima, seed_order

pytest.importorskip("numba")
from torchsar.region import _kernels as K  # only with numba


def _padded(f: np.ndarray, blocked: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """F and the free flags on the grid padded by one never-free pixel, as the kernel has
    them."""
    fp = np.pad(f, 1).reshape(-1)
    free = np.pad(~blocked, 1).astype(np.uint8).reshape(-1)
    return fp, free


def _unpad(idx: np.ndarray, w: int) -> np.ndarray:
    r, c = np.divmod(idx, w + 2)
    return (r - 1) * w + (c - 1)


class TestSum:
    @pytest.mark.parametrize("n", [*range(0, 300), 1000, 1023, 4097, 8191, 8192, 8193, 65537])
    def test_equals_numpy_add_reduce_bitwise(self, n):
        rng = np.random.default_rng(n)
        v = rng.exponential(size=n) * 10.0 ** rng.uniform(-8, 8, size=n)
        v[rng.random(n) < 0.1] = 0.0
        assert K.np_sum(v, n) == np.add.reduce(v)
        assert math.copysign(1.0, K.np_sum(v, n)) == math.copysign(1.0, np.add.reduce(v))

    def test_a_prefix_only(self):
        v = np.arange(20.0)
        assert K.np_sum(v, 9) == np.add.reduce(v[:9])


class TestGrow:
    @settings(max_examples=60)
    @given(
        st.integers(0, 2**31 - 1),
        st.sampled_from([4, 8]),
        st.integers(1, 6),
        st.sampled_from([0.1, 0.3, 0.5, 0.8]),
        st.integers(1, 30),
        st.integers(1, 30),
        st.sampled_from([0.0, 0.3, 0.7]),
    )
    def test_same_pixels_as_the_heap(self, seed, conn, n_init, tau, h, w, floor):
        """The first ``n_init`` pixels by rescanning, then the flood fixpoint: the heap's
        region (budget None: no flood in the Python path), the seed first."""
        rng = np.random.default_rng(seed)
        f = ndimage.uniform_filter(rng.gamma(1.0, 1.0, size=(h, w)), 3)
        if rng.random() < 0.3:
            f = f.round(1)  # ties
        blocked = rng.random(f.shape) < 0.1
        start = int(rng.integers(f.size))
        blocked.flat[start] = False
        g = Grid.new(f, connectivity=conn)
        g.free2d()[blocked] = 0
        want = grow(g, start, 1, tau=tau, n_init=n_init, budget=None, floor=floor)
        fp, free = _padded(f, blocked)
        offs = np.array(
            [-(w + 2), w + 2, -1, 1, -(w + 3), -(w + 1), w + 1, w + 3][:conn], dtype=np.int32
        )
        region, cand = np.empty(h * w, np.int32), np.empty(h * w, np.int32)
        stamp = np.zeros(fp.size, np.int32)
        seed_p = start + 2 * (start // w) + w + 3
        low = floor * f.flat[start] if floor > 0 else -np.inf
        n = K._grow(fp, free, stamp, 1, seed_p, tau, n_init, offs, region, cand, low)
        got = _unpad(region[:n], w)
        assert got[0] == start
        np.testing.assert_array_equal(np.sort(got), np.sort(want))
        assert (f.flat[want[1:]] >= floor * f.flat[start]).all()  # nothing below the floor


class TestSeeds:
    @settings(max_examples=60)
    @given(
        st.integers(0, 2**31 - 1),
        st.sampled_from([1, 3, 5, 7]),
        st.integers(1, 14),
        st.integers(1, 14),
        st.booleans(),
    )
    def test_equal_local_maxima_in_seed_order_and_reference(self, seed, window, h, w, plateaus):
        rng = np.random.default_rng(seed)
        f = rng.integers(0, 3, (h, w)).astype(float) if plateaus else rng.random((h, w))
        got = K.seeds(f.reshape(-1), h, w, window).tolist()
        ft = torch.from_numpy(f)
        assert got == seed_order(ft, local_maxima(ft[None, None], window)[0, 0]).tolist()
        assert got == ref.seeds(f, window)


class TestComponents:
    @settings(max_examples=80)
    @given(
        st.integers(0, 2**31 - 1),
        st.integers(1, 25),
        st.integers(1, 25),
        st.floats(0.0, 1.0),
        st.booleans(),
    )
    def test_equal_scipy_label_and_its_numbering(self, seed, h, w, density, blobs):
        rng = np.random.default_rng(seed)
        noise = rng.random((h, w))
        if blobs:
            noise = ndimage.uniform_filter(noise, 3)
        mask = noise < (np.quantile(noise, density) if blobs else density)
        lab = np.empty(h * w, np.int64)
        parent = np.empty(h * w, np.int64)
        for conn8 in (False, True):
            structure = np.ones((3, 3), bool) if conn8 else None
            want, n = ndimage.label(mask, structure=structure)
            got = K._components(mask.reshape(-1), h, w, conn8, lab, parent)
            assert got == n
            np.testing.assert_array_equal(lab.reshape(h, w), want)


_SHAPES = (st.integers(0, 2**31 - 1), st.integers(3, 18), st.integers(3, 18))
_CORNER = st.tuples(st.integers(0, 12), st.integers(0, 12))


class TestFinishing:
    @given(*_SHAPES, _CORNER)
    def test_fill_holes_equal_reference(self, seed, h, w, corner):
        stat, region_id, z = _painted(seed, h, w, corner)
        state = _state(stat, region_id, z)
        want_stat, want_id = ref.fill_holes(stat, region_id, state.k, lambda t: z[t - 1])
        s, i = state.stat.copy(), state.region_id.copy()
        K.fill_holes(s, i, h, w, float(state.k), z.astype(np.float64))
        np.testing.assert_array_equal(s.reshape(h, w), want_stat)
        holes = want_stat != stat
        np.testing.assert_array_equal(i.reshape(h, w)[holes], want_id[holes])
        np.testing.assert_array_equal(i.reshape(h, w)[~holes], region_id[~holes])

    @given(*_SHAPES, _CORNER, st.integers(2, 12))
    def test_drop_small_equal_reference(self, seed, h, w, corner, min_size):
        stat, region_id, z = _painted(seed, h, w, corner)
        k = _state(stat, region_id, z).k
        small = ref.small_objects(stat > k, min_size)
        s = stat.reshape(-1).copy()
        dropped = K.drop_small_objects(s, region_id.reshape(-1), h, w, float(k), min_size, z.size)
        np.testing.assert_array_equal(s.reshape(h, w), np.where(small, -np.inf, stat))
        assert set(np.flatnonzero(dropped).tolist()) == set(np.unique(region_id[small]).tolist())

    @given(*_SHAPES, _CORNER, st.integers(0, 3))
    def test_merged_labels_equal_reference(self, seed, h, w, corner, merge):
        stat, _, _ = _painted(seed, h, w, corner)
        mask = stat > 2.0
        got = K.merged_labels(mask.reshape(-1), h, w, merge).reshape(h, w)
        np.testing.assert_array_equal(got, ref.merged_labels(mask, merge))


class _DespeckleCompiled:
    """Stands in for ``torchsar._jit`` in the speckle filters: their one-sweep kernels in
    both runs, so the comparison isolates the region kernels (the kernels' own agreement
    with the tensor code is in tests/test_box_kernels.py)."""

    @staticmethod
    def for_tensor(t: torch.Tensor) -> bool:
        return t.device.type == "cpu" and t.dtype in (torch.float32, torch.float64)


def _search(x: torch.Tensor, compiled: bool, **options):
    _local = importlib.import_module("torchsar.speckle._local")  # decides for every filter
    old, pinned = _jit.ENABLED, _local._jit
    _jit.ENABLED = compiled
    _local._jit = _DespeckleCompiled
    try:
        return region_search(x, **options)
    finally:
        _jit.ENABLED = old
        _local._jit = pinned


def _rows_equal(a, b) -> bool:
    """Every field equal, NaN equal to NaN, floats compared bit for bit."""
    if len(a.rows) != len(b.rows):
        return False
    for ra, rb in zip(a.rows, b.rows, strict=True):
        for name in ra.__dataclass_fields__:
            u, v = getattr(ra, name), getattr(rb, name)
            if type(u) is not type(v):
                return False
            if isinstance(u, float):
                if np.float64(u).tobytes() != np.float64(v).tobytes():
                    return False
            elif u != v:
                return False
    return True


def _assert_same(x: torch.Tensor, **options) -> None:
    a, b = _search(x, False, **options), _search(x, True, **options)
    da, db = a.detection, b.detection
    assert da.statistic.dtype == db.statistic.dtype
    np.testing.assert_array_equal(
        da.statistic.numpy().view(np.uint8), db.statistic.numpy().view(np.uint8)
    )
    assert torch.equal(da.mask, db.mask)
    assert torch.equal(da.labels, db.labels)
    assert all(_rows_equal(p, q) for p, q in zip(a.tables, b.tables, strict=True))


OPTIONS = [
    {},
    {"preset": "paper"},
    {"connectivity": 8, "blocking": "targets"},
    {"preset": "paper", "blocking": "targets", "target_on": "despeckled"},
    {"lowpass": 5, "merge": 2, "n_init": 1, "tau": 0.3},
    {"lowpass": None, "merge": None, "min_size": 5, "max_size": 300, "guard": 0},
    {"preset": "paper", "fill_holes": True, "max_fraction": 0.05, "background": 1, "k": 0.0},
    {"floor": 0.05},
    {"preset": "paper", "floor": 0.5, "connectivity": 8},
]


@pytest.mark.parametrize(
    "options", OPTIONS, ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items())
)
def test_compiled_equals_python_on_chips(options):
    """Bit-identical statistic, mask, labels and tables on simulated 128x128 chips."""
    for seed in range(3):
        _assert_same(ts.simulate.chips(4, seed=seed).image, **options)


@pytest.mark.parametrize(
    "options", OPTIONS, ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items())
)
def test_compiled_equals_python_on_odd_shapes(options):
    """Non-square images with extended targets touching the border, float64 and float32."""
    rng = np.random.default_rng(len(str(options)))
    for h, w in [(37, 53), (61, 29), (1, 40), (9, 1)]:
        clean = np.ones((h, w))
        clean[h // 4 : h // 2 + 1, : max(w // 3, 1)] = 9.0
        clean[-(h // 5 + 1) :, -(w // 4 + 1) :] = 5.0
        img = clean * rng.gamma(2.0, 0.5, size=(2, 1, h, w))
        x = torch.from_numpy(img)
        if min(h, w) >= 5:  # the default filter's window
            _assert_same(x, **options)
        _assert_same(x.float(), despeckle=None, **options)


@pytest.mark.slow
@pytest.mark.parametrize("model", ["gamma", "k", "weibull", "lognormal"])
def test_compiled_equals_python_on_many_chips_and_scenes(model):
    """The broad check (``-m slow``): 64 chips and two 512x512 scenes (buildings, roads,
    clutter edges: floods larger than the pairwise sums' blocks) per clutter model, both
    presets, and a floor on scenes."""
    for seed in range(8):
        x = ts.simulate.chips(8, seed=seed, model=model).image
        for options in ({}, {"preset": "paper"}):
            _assert_same(x, **options)
    scenes = ts.simulate.scenes(2, seed=1, model=model).image
    for options in (
        {},
        {"preset": "paper"},
        {"max_size": None, "max_fraction": None},
        {"floor": 0.02},
    ):
        _assert_same(scenes, **options)
