"""GeoTIFF pixel spacing from hand-written ModelPixelScale and GeoKeyDirectory tags."""

from __future__ import annotations

import numpy as np
import pytest
import tifffile

from tests.io.writers import write_geotiff
from torchsar.io import geotiff_pixel_spacing


@pytest.mark.parametrize(
    ("model_type", "units", "expected"),
    [(1, 9001, (0.5, 0.75)), (2, 9001, None), (1, 9002, None)],  # projected m / geographic / feet
)
def test_spacing_only_for_projected_metres(tmp_path, model_type, units, expected):
    path = write_geotiff(tmp_path / "g.tif", model_type, units)
    assert geotiff_pixel_spacing(path) == expected


def test_plain_tiff_has_no_spacing(tmp_path):
    tifffile.imwrite(tmp_path / "p.tif", np.zeros((4, 6), np.float32))
    assert geotiff_pixel_spacing(tmp_path / "p.tif") is None
