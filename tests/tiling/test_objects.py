"""Scene objects: components merged across tile seams equal the components of the
untiled mask (a slow per-component reference), for masks and for real detectors."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.tiling._scenes import reference_objects, same_objects, scene
from torchsar import cfar
from torchsar.tiling import COLUMNS, SeamMerger, plan_tiles, scene_objects


def _merged(mask: np.ndarray, score: np.ndarray, tile, connectivity: int = 2):
    merger = SeamMerger(mask.shape, connectivity)
    for t in plan_tiles(mask.shape, tile, 0):
        merger.add(t, mask[t.core], score[t.core])
    return merger.table()


def test_snake_and_diagonal_contacts_across_corners():
    mask = np.zeros((12, 12), bool)
    mask[1, 1:11] = True  # crosses every vertical seam of a 3-px tiling
    mask[1:11, 10] = True  # then down across the horizontal seams
    mask[5, 5] = mask[6, 6] = True  # touching only diagonally, across a tile corner
    mask[8, 2] = mask[9, 4] = True  # separate pixels (no contact)
    score = np.arange(mask.size, dtype=np.float32).reshape(mask.shape)
    for tile in (1, 3, (4, 5), 6, 12):
        got = _merged(mask, score, tile)
        same_objects(got, reference_objects(mask, score))
    assert len(_merged(mask, score, 3)) == 4
    assert len(_merged(mask, score, 3, connectivity=1)) == 5  # the diagonal pair splits


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    h=st.integers(1, 40),
    w=st.integers(1, 40),
    th=st.integers(1, 17),
    tw=st.integers(1, 17),
    density=st.floats(0.05, 0.7),
    connectivity=st.sampled_from([1, 2]),
)
def test_any_tiling_of_any_mask_gives_the_untiled_components(
    seed, h, w, th, tw, density, connectivity
):
    rng = np.random.default_rng(seed)
    mask = rng.random((h, w)) < density
    score = rng.integers(0, 5, size=(h, w)).astype(np.float32)  # ties: raster-order peaks
    got = _merged(mask, score, (th, tw), connectivity)
    same_objects(got, reference_objects(mask, score, connectivity))


def test_empty_mask_and_columns():
    t = _merged(np.zeros((5, 7), bool), np.zeros((5, 7)), 3)
    assert list(t.columns) == list(COLUMNS) and len(t) == 0


@pytest.mark.parametrize("tile", [(16, 16), (23, 40), 100])
def test_ca_scene_objects_equal_untiled_components(tile):
    x = scene(80, 96, seed=5, seams=(16, 16))
    opts = {"guard": 2, "train": 3, "pfa": 1e-4}
    full = cfar.ca(torch.from_numpy(x)[None, None], **opts)
    want = reference_objects(full.mask[0, 0].numpy(), full.statistic[0, 0].numpy())
    assert len(want) > 5
    got = scene_objects(x, "ca", tile=tile, batch=2, **opts)
    same_objects(got, want)
