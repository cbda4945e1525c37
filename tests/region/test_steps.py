"""Unit tests of the steps of the region-growing CFAR on tiny hand-made images."""

from __future__ import annotations

from unittest.mock import patch

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st
from scipy import ndimage

from tests.reference import region as ref
from torchsar.region import grow as grow_module
from torchsar.region.grow import Grid, grow
from torchsar.region.rings import crop_around, dilate, mean_std, ring_masks, ring_stats
from torchsar.region.seeds import local_maxima, seed_order


class TestSeeds:
    def test_local_maxima_5x5(self):
        f = torch.zeros(1, 1, 7, 7)
        f[0, 0, 1, 1], f[0, 0, 3, 4], f[0, 0, 6, 6] = 5.0, 4.0, 3.0
        got = local_maxima(f - 0.01 * torch.arange(49.0).reshape(1, 1, 7, 7))[0, 0]
        # (1, 1) and (3, 4) are 3 columns apart: both are maxima of their 5x5 windows
        assert got[1, 1] and got[3, 4] and got[6, 6]

    def test_equal_to_reference(self):
        g = torch.Generator().manual_seed(0)
        f = torch.rand(1, 1, 13, 17, generator=g, dtype=torch.float64)
        got = seed_order(f[0, 0], local_maxima(f)[0, 0]).tolist()
        assert got == ref.seeds(f[0, 0].numpy())

    @given(
        st.integers(0, 10_000),
        st.sampled_from([1, 3, 5, 7]),
        st.integers(1, 12),
        st.integers(1, 12),
    )
    def test_plateaus_and_borders_equal_reference(self, seed, window, h, w):
        f = torch.from_numpy(np.random.default_rng(seed).integers(0, 3, (h, w)).astype(float))
        got = seed_order(f, local_maxima(f[None, None], window)[0, 0]).tolist()
        assert got == ref.seeds(f.numpy(), window)

    def test_brightest_first_ties_by_index(self):
        f = torch.tensor([[2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0], [0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0]])
        order = seed_order(f, local_maxima(f[None, None])[0, 0]).tolist()
        assert order == [10, 0, 6]  # the 3 first, then the two tied 2's by flat index

    def test_window(self):
        f = torch.tensor([[[[3.0, 0.0, 2.0]]]])
        assert local_maxima(f, 3)[0, 0, 0].tolist() == [True, False, True]
        assert local_maxima(f, 5)[0, 0, 0].tolist() == [True, False, False]


def _grid(a) -> Grid:
    return Grid.new(np.asarray(a, dtype=np.float64))


class TestGrow:
    def test_order_most_similar_first(self):
        # a row: the seed 10, then 9.5 (left) and 8 (right): N=1 -> mu_N = 10
        g = _grid([[7.5, 9.5, 10.0, 8.0, 9.9]])
        out = grow(g, 2, 1, tau=0.3, n_init=1, budget=None).tolist()
        assert out == [2, 1, 3, 4, 0]  # |9.5-10| < |8-10|; then 9.9 (0.1) before 7.5 (2.5)

    def test_stops_when_psi_exceeds_tau(self):
        g = _grid([[10.0, 7.1, 6.9, 10.0]])  # tau * beta = 3: 7.1 passes, 6.9 does not
        assert grow(g, 0, 1, tau=0.3, n_init=1, budget=None).tolist() == [0, 1]

    def test_mu_n_is_mean_of_first_n(self):
        # first pixels 10, 7.2 (n_init=2 -> mu_N = 8.6); then 5.9 passes (|5.9-8.6| = 2.7 <= 3)
        g = _grid([[10.0, 7.2, 5.9]])
        assert grow(g, 0, 1, tau=0.3, n_init=2, budget=None).tolist() == [0, 1, 2]
        # with n_init=1 the reference stays 10 and 5.9 fails (4.1 > 3)
        g = _grid([[10.0, 7.2, 5.9]])
        assert grow(g, 0, 1, tau=0.3, n_init=1, budget=None).tolist() == [0, 1]

    def test_beta_grows(self):
        # beta becomes 12 after adding 12, which widens the tolerance to 3.6 for 6.5
        g = _grid([[10.0, 12.0, 6.5]])
        assert grow(g, 0, 1, tau=0.3, n_init=1, budget=None).tolist() == [0, 1, 2]

    def test_four_connectivity(self):
        a = [[10.0, 0.0], [0.0, 10.0]]
        assert grow(_grid(a), 0, 1, tau=0.3, n_init=1).tolist() == [0]
        g8 = Grid.new(np.asarray(a), connectivity=8)
        assert sorted(grow(g8, 0, 1, tau=0.3, n_init=1).tolist()) == [0, 3]

    @given(st.integers(1, 7), st.integers(1, 7), st.sampled_from([4, 8]))
    def test_neighbours_are_the_in_image_ones(self, h, w, conn):
        nbrs = Grid.new(np.zeros((h, w)), connectivity=conn).neighbours()
        for p in range(h * w):
            r, c = divmod(p, w)
            want = {
                rr * w + cc
                for rr in range(r - 1, r + 2)
                for cc in range(c - 1, c + 2)
                if 0 <= rr < h and 0 <= cc < w and (rr, cc) != (r, c)
                if conn == 8 or rr == r or cc == c
            }
            got = nbrs(p)
            assert len(got) == len(want) and set(got) == want

    def test_blocked_pixels_are_not_entered(self):
        g = _grid([[10.0, 10.0, 10.0]])
        g.free[1] = 0
        assert grow(g, 0, 1, tau=0.3, n_init=1).tolist() == [0]

    @given(st.integers(0, 10_000), st.sampled_from([4, 8]), st.integers(1, 6))
    def test_flood_finish_equals_heap(self, seed, conn, n_init):
        rng = np.random.default_rng(seed)
        f = rng.gamma(2.0, 1.0, size=(20, 23))
        f[5:12, 6:15] += 6.0
        blocked = rng.random(f.shape) < 0.1
        start = int(np.argmax(f))
        for floor in (0.0, 0.4):  # the floor holds in the heap and in the flood finish
            out = []
            for budget in (None, 1, 5):
                g = Grid.new(f, connectivity=conn)
                g.free2d()[blocked] = 0
                out.append(
                    np.sort(grow(g, start, 1, tau=0.3, n_init=n_init, budget=budget, floor=floor))
                )
            np.testing.assert_array_equal(out[0], out[1])
            np.testing.assert_array_equal(out[0], out[2])
            assert (f.flat[out[0]] >= floor * f.flat[start]).all()

    @pytest.mark.parametrize("steps", [0, 1, 8])
    @given(st.integers(0, 10_000), st.sampled_from([4, 8]))
    def test_widening_floods_equal_heap(self, steps, seed, conn):
        """A dim seed in smoothed speckle: ``beta`` grows over several floods, each found by
        labelling only (0 steps) or by extending the previous one first; all equal the heap."""
        rng = np.random.default_rng(seed)
        f = ndimage.uniform_filter(rng.gamma(1.0, 1.0, size=(24, 27)), 3)
        blocked = rng.random(f.shape) < 0.05
        start = int(rng.integers(f.size))
        blocked.flat[start] = False
        out = []
        for budget in (None, 3):
            g = Grid.new(f, connectivity=conn)
            g.free2d()[blocked] = 0
            with patch.object(grow_module, "_STEPS", steps):
                out.append(np.sort(grow(g, start, 1, tau=0.4, n_init=2, budget=budget)))
        np.testing.assert_array_equal(out[0], out[1])

    @pytest.mark.parametrize("label_max", [0, 2000, 1 << 16])
    @given(seed=st.integers(0, 10_000), conn=st.sampled_from([4, 8]))
    def test_crop_floods_equal_heap(self, label_max, seed, conn):
        """Images above the labelling size are flooded on growing crops (margin doubling,
        labelling or skimage's flood per crop size); below it, whole: all equal the heap."""
        rng = np.random.default_rng(seed)
        f = rng.gamma(4.0, 1.0, size=(64, 72))
        f[10:50, 8:60] = rng.normal(20.0, 1.0, size=(40, 52))  # the flood crosses crop edges
        blocked = rng.random(f.shape) < 0.05
        blocked[30, 30] = False
        start = 30 * 72 + 30
        out = []
        with patch.object(grow_module, "_LABEL_MAX", label_max):
            for budget in (None, 3):
                g = Grid.new(f, connectivity=conn)
                g.free2d()[blocked] = 0
                out.append(np.sort(grow(g, start, 1, tau=0.5, n_init=2, budget=budget)))
        assert out[0].size > 400
        np.testing.assert_array_equal(out[0], out[1])

    @given(st.integers(0, 10_000))
    def test_equal_to_reference(self, seed):
        rng = np.random.default_rng(seed)
        f = rng.gamma(3.0, 1.0, size=(9, 11))
        free = rng.random(f.size) > 0.1
        start = int(np.argmax(np.where(free, f.reshape(-1), -1)))
        g = Grid.new(f)
        g.free[:] = free.astype(np.uint8).tobytes()
        got = grow(g, start, 1, tau=0.3, n_init=4, budget=None).tolist()
        assert got == ref.grow(f, start, free, 0.3, 4)


class TestRings:
    def test_single_pixel_shapes(self):
        t = np.zeros((15, 15), dtype=bool)
        t[7, 7] = True
        k, c = ring_masks(t, 3, 3)
        assert int(k.sum()) == 7 * 7 and k[4:11, 4:11].all()
        assert int(c.sum()) == 13 * 13 - 7 * 7 and not (c & k).any()
        assert c[1, 1] and c[13, 13] and not c[0, 0]

    def test_follow_region_shape(self):
        t = np.zeros((12, 12), dtype=bool)
        t[5, 2:10] = True  # a horizontal bar
        k, c = ring_masks(t, 1, 1)
        assert int(k.sum()) == 3 * 10
        assert int(c.sum()) == 5 * 12 - 3 * 10
        assert not c[5, 5] and c[3, 5] and c[7, 5] and not c[2, 5]

    def test_equal_to_reference(self):
        rng = np.random.default_rng(1)
        t = rng.random((14, 16)) > 0.85
        k, c = ring_masks(t, 2, 3)
        rk, rc = ref.rings(np.flatnonzero(t).tolist(), t.shape, 2, 3)
        np.testing.assert_array_equal(k, rk)
        np.testing.assert_array_equal(c, rc)

    @given(
        st.integers(0, 10_000),
        st.integers(1, 30),
        st.integers(1, 30),
        st.integers(0, 4),
        st.integers(0, 4),
    )
    def test_random_masks_equal_reference(self, seed, h, w, guard, background):
        t = np.random.default_rng(seed).random((h, w)) < 0.1
        k, c = ring_masks(t, guard, background)
        rk, rc = ref.rings(np.flatnonzero(t).tolist(), t.shape, guard, background)
        np.testing.assert_array_equal(k, rk)
        np.testing.assert_array_equal(c, rc)

    @given(st.integers(0, 10_000), st.integers(1, 40), st.integers(1, 40), st.integers(1, 9))
    def test_dilate_equals_maximum_filter(self, seed, h, w, radius):
        m = np.random.default_rng(seed).random((h, w)) < 0.05
        want = ndimage.maximum_filter(m, size=2 * radius + 1, mode="constant", cval=False)
        np.testing.assert_array_equal(dilate(m, radius), want)

    def test_dilate_zero_radius(self):
        m = np.eye(3, dtype=bool)
        np.testing.assert_array_equal(dilate(m, 0), m)

    def test_crop_is_clipped_to_image(self):
        crop = crop_around(np.array([0, 1]), (10, 10), 4)
        assert (crop.r0, crop.r1, crop.c0, crop.c1) == (0, 5, 0, 6)
        assert crop.region[0, :2].all() and int(crop.region.sum()) == 2


def _stats_case():
    raw = np.ones((11, 11))
    raw[::2] = 3.0  # background alternates 3 / 1 by rows
    raw[5, 5] = 20.0
    t = np.array([5 * 11 + 5])
    return raw, crop_around(t, (11, 11), 3)


class TestRingStats:
    @given(st.integers(0, 10_000), st.integers(1, 2000), st.floats(-6, 6))
    def test_mean_std_equal_numpy_bitwise(self, seed, n, scale):
        v = np.random.default_rng(seed).gamma(1.0, 10.0**scale, n)
        mu, sigma = mean_std(v)
        assert mu == float(v.mean()) and sigma == float(v.std())

    def test_hand_computed(self):
        raw, crop = _stats_case()
        none = np.zeros((11, 11), dtype=bool)
        low = np.zeros((11, 11))
        rs = ring_stats(crop, raw, raw, low, none, 1, 2)
        # ring of Chebyshev distance 2..3 around (5, 5): rows 2,8 (dist 3, row even -> 3)...
        ii, jj = np.mgrid[:11, :11]
        d = np.maximum(abs(ii - 5), abs(jj - 5))
        vals = raw[(d >= 2) & (d <= 3)]
        assert rs.mu_t == 20.0 and rs.n_background == vals.size == 40
        assert rs.mu_c == pytest.approx(vals.mean()) and rs.sigma_c == pytest.approx(vals.std())

    def test_lowpass_censoring(self):
        raw, crop = _stats_case()
        none = np.zeros((11, 11), dtype=bool)
        low = raw.copy()
        low[8] = 25.0  # row 8 looks brighter than the target after low-pass: censored
        rs = ring_stats(crop, raw, raw, low, none, 1, 2)
        assert rs.n_background == 40 - 7
        ii, jj = np.mgrid[:11, :11]
        d = np.maximum(abs(ii - 5), abs(jj - 5))
        kept = raw[(d >= 2) & (d <= 3) & (ii != 8)]
        assert rs.mu_c == pytest.approx(kept.mean())

    def test_taken_censoring(self):
        raw, crop = _stats_case()
        taken = np.zeros((11, 11), dtype=bool)
        taken[2, :] = True  # an earlier target: never part of this background
        low = np.zeros((11, 11))
        rs = ring_stats(crop, raw, raw, low, taken, 1, 2)
        assert rs.n_background == 40 - 7


def _state(stat: np.ndarray, region_id: np.ndarray, z: np.ndarray):
    """An image state holding a painted statistic, region ids and one table row per id."""
    from torchsar.region.detector import _ImageState
    from torchsar.region.params import resolve_params
    from torchsar.region.table import RegionRow, RegionTable

    h, w = stat.shape
    state = _ImageState(torch.zeros(h, w, dtype=torch.float64), resolve_params("torchsar"))
    state.stat, state.region_id = stat.reshape(-1).copy(), region_id.reshape(-1).copy()
    state.table = RegionTable(
        [RegionRow((0, 0), 1, 0.0, 0.0, 1.0, 20, float(v), bool(v > state.k), "") for v in z]
    )
    return state


def _painted(seed: int, h: int, w: int, corner: tuple[int, int], n_regions: int = 4):
    """Random region ids and statistics, regions only in a box from ``corner`` (so the
    accepted pixels may cover a small part of the image or touch its border)."""
    rng = np.random.default_rng(seed)
    region_id = rng.integers(0, n_regions + 1, size=(h, w)).astype(np.int32)
    z = rng.normal(size=n_regions) + 0.5
    z[0] = 3.0  # at least one accepted id
    stat = np.where(region_id > 0, z[region_id - 1], -np.inf)
    stat[rng.random((h, w)) < 0.3] = -np.inf  # unaccepted pixels, holes among them
    keep = np.zeros((h, w), dtype=bool)
    r, c = corner
    keep[r : r + max(h // 2, 3), c : c + max(w // 2, 3)] = True
    stat[~keep], region_id[~keep] = -np.inf, 0
    return stat, region_id, z


_SHAPES = (st.integers(0, 2**31 - 1), st.integers(3, 18), st.integers(3, 18))


class TestFillHoles:
    @given(*_SHAPES, st.tuples(st.integers(0, 12), st.integers(0, 12)))
    def test_equal_to_reference(self, seed, h, w, corner):
        from torchsar.region.detector import _fill_holes

        stat, region_id, z = _painted(seed, h, w, corner)
        state = _state(stat, region_id, z)
        want_stat, want_id = ref.fill_holes(stat, region_id, state.k, lambda t: z[t - 1])
        _fill_holes(state)
        np.testing.assert_array_equal(state.stat.reshape(h, w), want_stat)
        holes = want_stat != stat
        np.testing.assert_array_equal(state.region_id.reshape(h, w)[holes], want_id[holes])


class TestObjects:
    @given(*_SHAPES, st.tuples(st.integers(0, 12), st.integers(0, 12)), st.integers(2, 12))
    def test_drop_small_equal_reference(self, seed, h, w, corner, min_size):
        from torchsar.region.detector import _drop_small_objects

        stat, region_id, z = _painted(seed, h, w, corner)
        state = _state(stat, region_id, z)
        small = ref.small_objects(stat > state.k, min_size)
        _drop_small_objects(state, min_size)
        np.testing.assert_array_equal(state.stat.reshape(h, w), np.where(small, -np.inf, stat))
        dropped = {int(t) for t in np.unique(region_id[small])}
        for t, row in enumerate(state.table.rows, start=1):
            assert (row.reason == "too_small") == (t in dropped)

    @given(*_SHAPES, st.tuples(st.integers(0, 12), st.integers(0, 12)), st.integers(0, 3))
    def test_merged_labels_equal_reference(self, seed, h, w, corner, merge):
        from torchsar.region.detector import _labels

        stat, region_id, z = _painted(seed, h, w, corner)
        state = _state(stat, region_id, z)
        mask = (stat > state.k).reshape(-1)
        got = _labels(state, mask, merge)
        np.testing.assert_array_equal(got, ref.merged_labels(stat > state.k, merge))
