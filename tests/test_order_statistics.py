"""The exact ring order statistic: both algorithms against sorting, across tile boundaries."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.reference.cfar import kth_smallest, ring_cells
from torchsar.order_statistics import bisection, ring_order_statistic
from torchsar.order_statistics.histogram import histogram_select
from torchsar.windows import Ring

ALGORITHMS = {"bisection": bisection.bisection_select, "histogram": histogram_select}


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


@pytest.mark.parametrize("algorithm", sorted(ALGORITHMS))
@pytest.mark.parametrize("budget", [None, 700])
def test_matches_sorting_with_varying_ranks_masks_and_tiles(monkeypatch, algorithm, budget):
    if budget is not None:  # force many small bisection tiles (planes, rows and columns)
        monkeypatch.setattr(bisection, "CELL_BUDGET", budget)
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
