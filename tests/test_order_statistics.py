"""The exact ring order statistic: every pixel against sorting, across tile boundaries."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import torchsar.order_statistics as osm
from tests.reference.cfar import kth_smallest, ring_cells
from torchsar.windows import Ring


def reference(img: np.ndarray, ring: Ring, k: np.ndarray) -> np.ndarray:
    out = np.zeros_like(img)
    for i in range(img.shape[0]):
        for j in range(img.shape[1]):
            if k[i, j] > 0:
                out[i, j] = kth_smallest(ring_cells(img, i, j, ring.guard, ring.train), k[i, j])
    return out


@pytest.mark.parametrize("budget", [None, 700])
def test_matches_sorting_with_varying_ranks_and_tiles(monkeypatch, budget):
    if budget is not None:  # force many small tiles (planes, rows and columns)
        monkeypatch.setattr(osm, "_CELL_BUDGET", budget)
    rng = np.random.default_rng(7)
    imgs = rng.exponential(size=(3, 19, 23))
    ring = Ring(1, 2)
    counts = np.stack(
        [[[len(ring_cells(im, i, j, 1, 2)) for j in range(23)] for i in range(19)] for im in imgs]
    )
    k = np.minimum(counts, rng.integers(0, 25, size=counts.shape))
    got = osm.ring_order_statistic(
        torch.from_numpy(imgs)[:, None], ring, torch.from_numpy(k)[:, None]
    )
    for p in range(3):
        np.testing.assert_array_equal(got[p, 0].numpy(), reference(imgs[p], ring, k[p]))


def test_large_ring_count_above_255():
    img = np.random.default_rng(2).integers(0, 50, (40, 40)).astype(np.float32)
    ring = Ring(2, 6)  # N = 289 - 25 = 264 > 255: int16 counters
    k = np.full(img.shape, 200)
    got = osm.ring_order_statistic(
        torch.from_numpy(img)[None, None], ring, torch.from_numpy(k)[None, None]
    )
    for i, j in [(20, 20), (8, 8), (31, 12)]:
        assert got[0, 0, i, j].item() == kth_smallest(ring_cells(img, i, j, 2, 6), 200)


def test_wide_ring_fallback(monkeypatch):
    monkeypatch.setattr(osm, "_CELL_BUDGET", 100)  # (2o+1)^2 > budget / 2: unfold path
    img = np.random.default_rng(4).exponential(size=(12, 13))
    ring = Ring(1, 2)
    k = np.full(img.shape, 5)
    got = osm.ring_order_statistic(
        torch.from_numpy(img)[None, None], ring, torch.from_numpy(k)[None, None]
    )
    np.testing.assert_array_equal(got[0, 0].numpy(), reference(img, ring, np.minimum(k, 100)))
