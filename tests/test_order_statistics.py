"""The exact ring order statistic: every algorithm (bisection, histogram, the compiled rank
bitset) against sorting and scipy's rank_filter, across tile boundaries, for ties, extreme
values, tiny images, every rank and every dtype."""

from __future__ import annotations

import importlib.util
from contextlib import contextmanager

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from tests.reference.cfar import kth_smallest, ring_cells
from torchsar import _jit
from torchsar.order_statistics import bisection, ring_order_statistic
from torchsar.order_statistics.histogram import histogram_select
from torchsar.windows import Ring

HAVE_NUMBA = importlib.util.find_spec("numba") is not None
needs_numba = pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed")


def compiled_select(planes: torch.Tensor, ring: Ring, kk: torch.Tensor, vm) -> torch.Tensor:
    """The compiled rank bitset, as :func:`ring_order_statistic` calls it on CPU."""
    from torchsar.order_statistics.ring import _compiled

    return _compiled(planes, ring, kk, vm)


@contextmanager
def sweeping(how: str):
    """Every ring through the compiled kernel's column-bitset sweep (``"columns"``) or its
    bit-flip sweep (``"flips"``)."""
    from torchsar.order_statistics import _kernels

    old = _kernels.COLUMNS_MAX_OUTER
    _kernels.COLUMNS_MAX_OUTER = 10**6 if how == "columns" else -1
    try:
        yield
    finally:
        _kernels.COLUMNS_MAX_OUTER = old


def flips_select(planes: torch.Tensor, ring: Ring, kk: torch.Tensor, vm) -> torch.Tensor:
    """:func:`compiled_select` by the bit-flip sweep, whatever the ring."""
    with sweeping("flips"):
        return compiled_select(planes, ring, kk, vm)


ALGORITHMS = {"bisection": bisection.bisection_select, "histogram": histogram_select}
if HAVE_NUMBA:
    ALGORITHMS["compiled"] = compiled_select
    ALGORITHMS["compiled-flips"] = flips_select


def reference(img: np.ndarray, ring: Ring, k: np.ndarray, valid: np.ndarray | None = None):
    masked = img if valid is None else np.where(valid, img, np.nan)
    out = np.zeros_like(img)
    for i in range(img.shape[0]):
        for j in range(img.shape[1]):
            if k[i, j] > 0:
                cells = ring_cells(masked, i, j, ring.guard, ring.train)
                out[i, j] = kth_smallest(cells[~np.isnan(cells)], k[i, j])
    return out


def counts(img: np.ndarray, ring: Ring, valid: np.ndarray | None = None) -> np.ndarray:
    ones = np.ones_like(img) if valid is None else np.where(valid, 1.0, np.nan)
    h, w = img.shape
    return np.asarray(
        [
            [
                np.count_nonzero(~np.isnan(ring_cells(ones, i, j, ring.guard, ring.train)))
                for j in range(w)
            ]
            for i in range(h)
        ]
    )


def run(algorithm: str, imgs: np.ndarray, ring: Ring, k: np.ndarray, valid=None) -> np.ndarray:
    vm = None if valid is None else torch.from_numpy(valid)
    return ALGORITHMS[algorithm](torch.from_numpy(imgs), ring, torch.from_numpy(k), vm).numpy()


@pytest.mark.parametrize(
    ("algorithm", "groups"), [(a, "cpu") for a in sorted(ALGORITHMS)] + [("bisection", "device")]
)
@pytest.mark.parametrize("budget", [None, 700])
def test_matches_sorting_with_varying_ranks_masks_and_tiles(monkeypatch, algorithm, budget, groups):
    if groups == "device":  # the GPU's grouping: every piece of every plane in one group
        monkeypatch.setattr(bisection, "_COMPARE_BUDGET", bisection.DEVICE_COMPARE_BUDGET)
    if budget is not None:  # force many small tiles (planes, rows and columns)
        monkeypatch.setattr(bisection, "CELL_BUDGET", budget)
        if HAVE_NUMBA:
            from torchsar.order_statistics import _kernels

            monkeypatch.setattr(_kernels, "TILE_CELLS", budget)
            monkeypatch.setattr(_kernels, "COLUMN_TILE_CELLS", budget)
    rng = np.random.default_rng(7)
    imgs = rng.exponential(size=(3, 19, 23))
    valid = rng.random(imgs.shape) > 0.2
    ring = Ring(1, 2)
    for mask in (None, valid):
        cnt = np.stack(
            [counts(im, ring, None if mask is None else mask[p]) for p, im in enumerate(imgs)]
        )
        k = np.minimum(cnt, rng.integers(0, 25, size=cnt.shape))
        got = run(algorithm, imgs, ring, k, mask)
        for p in range(3):
            want = reference(imgs[p], ring, k[p], None if mask is None else mask[p])
            np.testing.assert_array_equal(got[p], want)


@pytest.mark.parametrize("algorithm", sorted(ALGORITHMS))
def test_large_ring_count_above_255_with_ties(algorithm):
    img = np.random.default_rng(2).integers(0, 50, (1, 40, 40)).astype(np.float32)
    ring = Ring(2, 6)  # N = 289 - 25 = 264 > 255: int16 counters; many tied values
    k = np.full(img.shape, 200)
    got = run(algorithm, img, ring, k)
    for i, j in [(20, 20), (8, 8), (31, 12)]:
        assert got[0, i, j] == kth_smallest(ring_cells(img[0], i, j, 2, 6), 200)


@settings(max_examples=25, deadline=None)
@given(
    h=st.integers(5, 30),
    w=st.integers(5, 30),
    guard=st.integers(0, 3),
    train=st.integers(1, 4),
    seed=st.integers(0, 2**16),
)
def test_histogram_equals_sorting_for_any_geometry(h, w, guard, train, seed):
    ring = Ring(guard, train)
    rng = np.random.default_rng(seed)
    img = rng.exponential(size=(1, h, w)).round(1)  # ties too
    k = np.minimum(counts(img[0], ring), rng.integers(0, ring.n + 1, size=(h, w)))[None]
    np.testing.assert_array_equal(run("histogram", img, ring, k)[0], reference(img[0], ring, k[0]))


def test_wide_ring_goes_to_the_histogram_and_stays_exact():
    img = np.random.default_rng(4).exponential(size=(30, 33))
    ring = Ring(2, 10)  # N = 600: beyond the bisection's range
    k = np.minimum(counts(img, ring), 450)
    got = ring_order_statistic(
        torch.from_numpy(img)[None, None], ring, torch.from_numpy(k)[None, None]
    )
    np.testing.assert_array_equal(got[0, 0].numpy(), reference(img, ring, k))


@pytest.mark.parametrize("train", [2, 10])
def test_batch_size_independent(train):
    x = torch.empty(5, 2, 24, 27).exponential_(generator=torch.Generator().manual_seed(3))
    ring = Ring(1, train)
    k = torch.full(x.shape, 7)
    whole = ring_order_statistic(x, ring, k)
    parts = torch.cat([ring_order_statistic(x[i : i + 1], ring, k[i : i + 1]) for i in range(5)])
    assert torch.equal(whole, parts)


@pytest.mark.parametrize("dtype", [torch.bfloat16, torch.float16])
@pytest.mark.parametrize("train", [2, 10])
def test_low_precision_is_exact(dtype, train):
    x = torch.empty(1, 1, 25, 25).exponential_(generator=torch.Generator().manual_seed(5))
    ring, k = Ring(1, train), torch.full((1, 1, 25, 25), 3)
    got = ring_order_statistic(x.to(dtype), ring, k)
    assert got.dtype == dtype
    assert torch.equal(got.float(), ring_order_statistic(x.to(dtype).float(), ring, k))


def test_leaves_thread_settings_alone(monkeypatch):
    def refuse(_n: int) -> None:
        raise AssertionError("torch.set_num_threads called")

    monkeypatch.setattr(torch, "set_num_threads", refuse)
    x = torch.rand(1, 1, 30, 30)
    for train in (2, 10):
        ring_order_statistic(x, Ring(1, train), torch.ones(1, 1, 30, 30, dtype=torch.long))


def test_input_requiring_grad_is_read_not_differentiated():
    x = torch.rand(1, 1, 12, 12, requires_grad=True)
    got = ring_order_statistic(x, Ring(1, 1), torch.full((1, 1, 12, 12), 2))
    assert not got.requires_grad
    assert torch.equal(got, ring_order_statistic(x.detach(), Ring(1, 1), torch.full(x.shape, 2)))


def _sorted_rings(img: np.ndarray, ring: Ring) -> list[list[np.ndarray]]:
    """Every pixel's in-image ring values, sorted (``kth_smallest`` of each rank at once)."""
    h, w = img.shape
    return [
        [np.sort(ring_cells(img, i, j, ring.guard, ring.train)) for j in range(w)] for i in range(h)
    ]


def _reference_all(rings: list[list[np.ndarray]], rank: int) -> np.ndarray:
    """Every pixel's ``min(rank, count)``-th smallest in-image ring value (sorting)."""
    return np.asarray(
        [
            [cells[min(rank, cells.size) - 1] if cells.size else 0.0 for cells in row]
            for row in rings
        ],
        dtype=np.float64,
    )


def _ranks_for(count: np.ndarray, rank: int) -> torch.Tensor:
    return torch.from_numpy(np.minimum(count, rank))[None, None]


@pytest.fixture(scope="class", params=["columns", "flips"])
def sweep(request):
    """The class's tests once through each sweep of the compiled kernel."""
    with sweeping(request.param):
        yield request.param


@needs_numba
@pytest.mark.usefixtures("sweep")
class TestCompiled:
    """The compiled path of :func:`ring_order_statistic` (CPU, numba), through both of its
    sweeps (column bitsets and bit flips) whatever the ring."""

    @pytest.mark.parametrize(("guard", "train"), [(0, 1), (1, 1), (2, 4), (1, 3)])
    def test_every_rank_equals_rank_filter_and_sorting(self, guard, train):
        ring = Ring(guard, train)
        o = ring.outer
        img = np.random.default_rng(ring.n).exponential(size=(2 * o + 9, 2 * o + 6))
        x = torch.from_numpy(img)[None, None]
        fp = np.ones((2 * o + 1,) * 2, bool)
        fp[train : train + 2 * guard + 1, train : train + 2 * guard + 1] = False
        count, rings = counts(img, ring), _sorted_rings(img, ring)
        for rank in range(1, ring.n + 1):
            got = ring_order_statistic(x, ring, _ranks_for(count, rank))[0, 0].numpy()
            want = ndimage.rank_filter(img, rank - 1, footprint=fp)
            np.testing.assert_array_equal(got[o:-o, o:-o], want[o:-o, o:-o])
            np.testing.assert_array_equal(got, _reference_all(rings, rank))

    @settings(max_examples=40, deadline=None)
    @given(
        h=st.integers(1, 16),
        w=st.integers(1, 16),
        guard=st.integers(0, 3),
        train=st.integers(1, 4),
        kind=st.sampled_from(["ties", "constant", "extremes", "signed", "exponential"]),
        frac=st.floats(0.0, 1.0),
        seed=st.integers(0, 2**16),
    )
    def test_property_equals_sorting(self, h, w, guard, train, kind, frac, seed):
        """Tiny images (the window as large as or larger than the image), ties, constant
        images, extreme magnitudes (subnormals to the largest float, zeros of both signs,
        infinities), negative values, any rank up to the pixel's count."""
        rng = np.random.default_rng(seed)
        ring = Ring(guard, train)
        if kind == "ties":
            img = rng.integers(0, 3, (h, w)).astype(np.float64)
        elif kind == "constant":
            img = np.full((h, w), 2.5)
        elif kind == "extremes":
            pool = np.array(
                [
                    0.0,
                    -0.0,
                    5e-324,
                    1e-310,
                    np.finfo(float).tiny,
                    1.0,
                    np.finfo(float).max,
                    np.inf,
                    -np.inf,
                    -np.finfo(float).max,
                ]
            )
            img = rng.choice(pool, size=(h, w))
        elif kind == "signed":
            img = rng.normal(size=(h, w))
        else:
            img = rng.exponential(size=(h, w))
        rank = max(1, round(frac * ring.n))
        for dtype in (np.float64, np.float32):
            with np.errstate(over="ignore"):  # the largest float64 becomes inf in float32
                a = img.astype(dtype)
            got = ring_order_statistic(
                torch.from_numpy(a)[None, None], ring, _ranks_for(counts(a, ring), rank)
            )[0, 0].numpy()
            want = _reference_all(_sorted_rings(a, ring), rank)
            np.testing.assert_array_equal(got, want.astype(dtype))

    @pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16, torch.float32, torch.float64])
    def test_every_dtype_equals_the_python_path(self, dtype):
        x = torch.empty(3, 2, 21, 26).exponential_(generator=torch.Generator().manual_seed(1))
        x = x.to(dtype)
        ring = Ring(1, 3)
        k = torch.randint(0, ring.n + 1, x.shape, generator=torch.Generator().manual_seed(2))
        k = torch.minimum(k, torch.from_numpy(counts(np.zeros((21, 26)), ring)))
        valid = torch.rand(x.shape, generator=torch.Generator().manual_seed(3)) > 0.1
        low = (torch.rand(x.shape, generator=torch.Generator().manual_seed(4)) > 0.5).long()
        for vm, kv in ((None, k), (valid, low)):  # with a mask: ranks 0 and 1 (always valid)
            got = ring_order_statistic(x, ring, kv, valid=vm)
            old, _jit.ENABLED = _jit.ENABLED, False
            try:
                want = ring_order_statistic(x, ring, kv, valid=vm)
            finally:
                _jit.ENABLED = old
            assert got.dtype == dtype
            assert torch.equal(got, want)

    @pytest.mark.parametrize("cells", [200, 700, 2000])
    def test_tiles_equal_one_tile(self, monkeypatch, cells):
        """Planes cut into tiles (a halo each) give the same values as one tile."""
        from torchsar.order_statistics import _kernels

        x = torch.empty(2, 1, 45, 52).exponential_(generator=torch.Generator().manual_seed(6))
        ring = Ring(2, 3)
        k = torch.full((45, 52), 20)
        whole = ring_order_statistic(x, ring, k)
        monkeypatch.setattr(_kernels, "TILE_CELLS", cells)
        monkeypatch.setattr(_kernels, "COLUMN_TILE_CELLS", cells)
        assert _kernels.tile_side(45, 52, ring.outer) < 45
        assert torch.equal(ring_order_statistic(x, ring, k), whole)

    def test_per_plane_ranks(self):
        """A rank map per image and channel, not one shared map."""
        x = torch.empty(2, 3, 15, 17).exponential_(generator=torch.Generator().manual_seed(8))
        ring = Ring(1, 2)
        k = torch.arange(6).reshape(2, 3, 1, 1) + 1
        got = ring_order_statistic(x, ring, k)
        for b in range(2):
            for c in range(3):
                img = x[b, c].double().numpy()
                want = _reference_all(_sorted_rings(img, ring), int(k[b, c]))
                np.testing.assert_array_equal(got[b, c].double().numpy(), want)


@needs_numba
@pytest.mark.parametrize(("guard", "train"), [(2, 4), (3, 6), (4, 12), (8, 12)])
def test_both_sweeps_agree_on_wide_rings_with_masks_and_tiles(guard, train):
    """The column-bitset sweep and the bit-flip sweep on rings from the default OS-CFAR's
    to wider than the column sweep takes by default, tiled, with no-data and per-pixel
    ranks; the first ring also against sorting."""
    from torchsar.order_statistics import _kernels

    ring = Ring(guard, train)
    rng = np.random.default_rng(ring.n)
    img = rng.exponential(size=(2, 1, 61, 70)).astype(np.float32)
    img[0, 0, 20:24, 30:33] = 0.0  # ties
    valid = rng.random(img.shape) > 0.05
    cnt = np.stack([counts(img[p, 0], ring, valid[p, 0]) for p in range(2)])[:, None]
    k = torch.from_numpy(np.minimum(cnt, rng.integers(0, ring.n + 1, cnt.shape)))
    x, vm = torch.from_numpy(img), torch.from_numpy(valid)
    got = {}
    for how in ("columns", "flips"):
        with sweeping(how):
            got[how] = ring_order_statistic(x, ring, k, valid=vm)
    assert torch.equal(got["columns"], got["flips"])
    assert _kernels.by_columns(Ring(2, 4).outer) and not _kernels.by_columns(Ring(8, 12).outer)
    if ring.outer == 6:
        want = reference(img[1, 0], ring, k[1, 0].numpy(), valid[1, 0])
        np.testing.assert_array_equal(got["columns"][1, 0].numpy(), want)


@needs_numba
def test_bit_selection_equals_listing_the_bits():
    """The column sweep's branch-free selection (the word by counting, the bit by byte
    counts and a table) against the positions of the set bits listed one by one: random
    words and bitsets, one bit, every bit, the sign bit."""
    from numba import njit

    from torchsar.order_statistics import _kernels

    select = njit(lambda w, j: _kernels._select_bit(w, j))
    kth = njit(lambda bits, k: _kernels._kth(bits, k, np.uint64(bits.size)))
    rng = np.random.default_rng(5)
    words = [np.int64(-1), np.int64(1), np.int64(-(2**63)), np.int64(2**62)]
    words += list(rng.integers(-(2**63), 2**63 - 1, 300, dtype=np.int64))
    for w in words:
        pos = [i for i in range(64) if (int(w) >> i) & 1]
        for j in range(len(pos)):
            assert select(w, j) == pos[j]
    for _ in range(300):
        n = int(rng.integers(1, 20))
        bits = rng.integers(-(2**63), 2**63 - 1, n, dtype=np.int64)
        bits &= rng.integers(-(2**63), 2**63 - 1, n, dtype=np.int64)  # sparser
        bits[rng.random(n) < 0.3] = 0
        ranks = [64 * wi + i for wi in range(n) for i in range(64) if (int(bits[wi]) >> i) & 1]
        for k in {1, len(ranks), int(rng.integers(1, len(ranks) + 1))} if ranks else ():
            assert kth(bits, k) == ranks[k - 1]
