"""Reduced spotlight systems shared by the motion tests (Table 1 except aperture and image size)."""

from __future__ import annotations

import warnings

import pytest

from torchsar.motion import SpotlightParams


def make_params(**kw) -> SpotlightParams:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return SpotlightParams.from_system(**kw)


@pytest.fixture(scope="session")
def small() -> SpotlightParams:
    """150 pulses (1 m azimuth resolution), 256 x 256 images: ~0.7 m pixels."""
    return make_params(azimuth_resolution=1.0, image_size=(256, 256))


@pytest.fixture(scope="session")
def tiny() -> SpotlightParams:
    """30 pulses, 64 x 64 images: for shape/batch/exception tests."""
    return make_params(azimuth_resolution=5.0, image_size=(64, 64))
