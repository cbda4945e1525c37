"""The region CFAR on tiles equals the untiled region CFAR: regions straddling seams and
corners, tiles smaller than the largest object, tiles not dividing the scene."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tests.tiling._scenes import reference_objects, same_objects, scene
from torchsar.region import region_cfar
from torchsar.tiling import UnsettledError, run_scene, scene_objects


@pytest.fixture(
    scope="module",
    params=[0, pytest.param(1, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow)],
)
def case(request):
    seed = request.param
    x = scene(150 + 7 * seed, 170 + 5 * seed, seed, seams=(40, 48), n_boxes=14, big=60)
    return x, region_cfar(torch.from_numpy(x)[None, None])


@pytest.mark.parametrize("tile", [(40, 48), pytest.param(33, marks=pytest.mark.slow), (57, 90)])
def test_tiled_region_cfar_equals_untiled(case, tile):
    x, full = case
    got = run_scene(x, "region", tile=tile, halo=32, max_halo=256)
    want_mask = full.mask[0, 0].numpy()
    assert want_mask.sum() > 3600  # the 60 x 60 object is detected: larger than any tile
    np.testing.assert_array_equal(got["mask"], want_mask)
    np.testing.assert_array_equal(got["statistic"], full.statistic[0, 0].numpy())


def test_region_scene_objects_equal_untiled_components(case):
    x, full = case
    want = reference_objects(full.mask[0, 0].numpy(), full.statistic[0, 0].numpy())
    got = scene_objects(x, "region", tile=(40, 48), halo=32, max_halo=256)
    same_objects(got, want)
    assert got["area"].min() >= 30  # the preset's min_size, applied after merging


def test_unsettled_tile_raises_instead_of_approximating():
    x = scene(160, 160, 0, seams=(40, 40), n_boxes=0, n_points=0, big=120)
    with pytest.raises(UnsettledError, match="max_halo=32"):  # the object spans 120 px
        run_scene(x, "region", tile=40, halo=16, max_halo=32)
