"""Bad scenes and options give typed errors naming the argument; an empty scene is valid."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from torchsar.errors import (
    InputTypeError,
    InputValueError,
    OptionError,
    ShapeError,
    WindowSizeError,
)
from torchsar.tiling import COLUMNS, as_scene, run_scene, scene_objects

X = np.random.default_rng(0).exponential(size=(40, 50)).astype(np.float32)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"tile": 0}, "tile"),
        ({"tile": -3}, "tile"),
        ({"tile": (8, 0)}, "tile"),
        ({"tile": 2.5}, "tile"),
        ({"halo": -1}, "halo"),
        ({"halo": 2}, "halo=2 is smaller than the operator's footprint reach"),
        ({"tile": 5}, "tile=.* smaller than the operator's 13x13 footprint"),
        ({"batch": 0}, "batch"),
        ({"device": "nope"}, "device"),
        ({"out": {"mask": np.zeros((3, 3), bool)}}, "out"),
        ({"bogus": 1}, "bogus"),
        ({"valid": np.ones((40, 50), bool)}, "valid"),
        ({"max_halo": 8}, "max_halo"),
    ],
)
def test_bad_options(kwargs, match):
    with pytest.raises(OptionError, match=match):
        run_scene(X, "ca", **{"tile": 16, **kwargs})


def test_bad_region_options():
    with pytest.raises(OptionError, match="tile"):
        run_scene(X, "region", tile=8)
    with pytest.raises(OptionError, match="halo"):
        run_scene(X, "region", tile=40, halo=3)
    with pytest.raises(OptionError, match="despeckle_reach"):
        run_scene(X, "region", tile=40, despeckle=lambda x: x)


def test_unknown_detector_and_filter_objects():
    with pytest.raises(OptionError, match="detector"):
        run_scene(X, "cfar9000")
    with pytest.raises(OptionError, match="speckle filter"):
        scene_objects(X, "lee")


def test_nan_in_a_tile_names_the_scene_and_the_window():
    x = X.copy()
    x[33, 44] = np.nan
    with pytest.raises(InputValueError, match=r"scene must be finite, got 1 NaN.*scene\["):
        run_scene(x, "ca", tile=16)
    x[33, 44] = -1.0
    with pytest.raises(InputValueError, match="non-negative"):
        scene_objects(x, "ca", tile=16)


@pytest.mark.parametrize(
    ("scene", "error", "match"),
    [
        (X.astype(np.complex64), InputTypeError, "complex"),
        (torch.zeros(2, 40, 50), ShapeError, "2-D"),
        ([[1.0, 2.0]], InputTypeError, "array-like"),
        (X.astype(bool), InputTypeError, "dtype"),
        (torch.ones(20, 20, requires_grad=True), InputTypeError, "grad"),
    ],
)
def test_bad_scenes(scene, error, match):
    with pytest.raises(error, match=match):
        as_scene(scene)


def test_scene_smaller_than_the_footprint():
    with pytest.raises(WindowSizeError, match="footprint"):
        run_scene(X[:10], "ca", tile=16)


@pytest.mark.parametrize("detector", ["ca", "region", "lee"])
def test_empty_scene_is_valid(detector):
    x = np.zeros((0, 50), np.float32)
    tile = 32 if detector == "region" else 16
    out = run_scene(x, detector, tile=tile)
    assert all(v.shape == (0, 50) for v in out.values())
    if detector != "lee":
        t = scene_objects(x, detector, tile=tile)
        assert len(t) == 0 and list(t.columns) == list(COLUMNS)
