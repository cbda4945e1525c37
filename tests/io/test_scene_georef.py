"""Georeferencing of scenes: affine models and tie-point grids against hand computations."""

from __future__ import annotations

import math

import numpy as np
import pytest
import tifffile

from tests.io.scene_writers import GEOGRAPHIC_KEYS
from torchsar.io import AffineGeoref, GeorefError, TiePointGrid, open_scene
from torchsar.io.georef import ground_spacing


def _write(path, tags, shape=(40, 60)):
    extratags = [(code, dtype, len(v), v, False) for code, dtype, v in tags]
    tifffile.imwrite(path, np.zeros(shape, np.uint16), tile=(16, 16), extratags=extratags)
    return path


def test_pixel_scale_and_tiepoint_give_lonlat_of_pixel_centres(tmp_path):
    # pixel (0, 0)'s corner at lon 10, lat 50; 0.001 x 0.002 degree pixels (PixelIsArea)
    path = _write(
        tmp_path / "g.tif",
        [
            (33550, "d", [0.001, 0.002, 0.0]),
            (33922, "d", [0.0, 0.0, 0.0, 10.0, 50.0, 0.0]),
            (34735, "H", GEOGRAPHIC_KEYS),
        ],
    )
    with open_scene(path) as scene:
        lon, lat = scene.georef.pixel_to_lonlat(np.array([0, 39, 10]), np.array([0, 59, 5]))
    np.testing.assert_allclose(lon, [10.0005, 10.0595, 10.0055], atol=1e-12)
    np.testing.assert_allclose(lat, [49.999, 49.921, 49.979], atol=1e-12)


def test_pixel_is_point_and_tiepoint_not_at_origin(tmp_path):
    keys = [1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 2, 2048, 0, 1, 4326]  # PixelIsPoint
    path = _write(
        tmp_path / "p.tif",
        [
            (33550, "d", [0.5, 0.25, 0.0]),
            (33922, "d", [4.0, 2.0, 0.0, -3.0, 7.0, 0.0]),
            (34735, "H", keys),
        ],
    )
    with open_scene(path) as scene:
        lon, lat = scene.georef.pixel_to_lonlat(2.0, 4.0)
    assert (float(lon), float(lat)) == (-3.0, 7.0)  # the tie point itself


def test_model_transformation_with_rotation(tmp_path):
    a, b, c, d, e, f = 0.001, 0.0003, 5.0, 0.0002, -0.001, 45.0
    m = [a, b, 0, c, d, e, 0, f, 0, 0, 0, 0, 0, 0, 0, 1]
    path = _write(tmp_path / "t.tif", [(34264, "d", m), (34735, "H", GEOGRAPHIC_KEYS)])
    rows, cols = np.array([0.0, 7.0, 39.0]), np.array([0.0, 3.0, 59.0])
    with open_scene(path) as scene:
        lon, lat = scene.georef.pixel_to_lonlat(rows, cols)
    np.testing.assert_allclose(lon, a * (cols + 0.5) + b * (rows + 0.5) + c)
    np.testing.assert_allclose(lat, d * (cols + 0.5) + e * (rows + 0.5) + f)


def test_projected_without_pyproj_gives_xy_and_says_so(tmp_path, monkeypatch):
    import torchsar.io.georef as georef

    monkeypatch.setattr(georef, "_pyproj", lambda: None)
    keys = [1, 1, 0, 3, 1024, 0, 1, 1, 3072, 0, 1, 32631, 3076, 0, 1, 9001]  # UTM 31N, m
    path = _write(
        tmp_path / "utm.tif",
        [
            (33550, "d", [10.0, 10.0, 0.0]),
            (33922, "d", [0.0, 0.0, 0.0, 500000.0, 5760000.0, 0.0]),
            (34735, "H", keys),
        ],
    )
    with open_scene(path) as scene:
        assert scene.pixel_spacing == (10.0, 10.0)
        g = scene.georef
        assert g.epsg == 32631 and not g.geographic and not g.has_lonlat
        x, y = g.pixel_to_xy(1, 2)
        assert (float(x), float(y)) == (500025.0, 5759985.0)
        with pytest.raises(GeorefError, match="EPSG:32631.*pyproj"):
            g.pixel_to_lonlat(1, 2)


def test_projected_with_pyproj(tmp_path):
    pytest.importorskip("pyproj")
    g = AffineGeoref((10.0, 0.0, 500000.0, 0.0, -10.0, 5760000.0), epsg=32631)
    lon, lat = g.pixel_to_lonlat(-0.5, -0.5)  # the model origin: a UTM 31N central point
    assert abs(float(lon) - 3.0) < 1e-9 and 51.9 < float(lat) < 52.1


def _bilinear_reference(rows, cols, lon, lat, r, c):
    """One pixel at a time: find the cell (the last one for points past the grid) and
    interpolate along columns, then rows."""
    i = max(k for k in range(len(rows) - 1) if rows[k] <= r or k == 0)
    j = max(k for k in range(len(cols) - 1) if cols[k] <= c or k == 0)
    u = (r - rows[i]) / (rows[i + 1] - rows[i])
    v = (c - cols[j]) / (cols[j + 1] - cols[j])
    out = []
    for g in (lon, lat):
        top = g[i][j] + v * (g[i][j + 1] - g[i][j])
        bottom = g[i + 1][j] + v * (g[i + 1][j + 1] - g[i + 1][j])
        out.append(top + u * (bottom - top))
    return out


def test_tie_point_grid_matches_slow_bilinear_reference(tmp_path):
    rng = np.random.default_rng(11)
    rows = [0.5, 80.5, 170.5, 299.5]
    cols = [0.5, 40.5, 133.5, 199.5, 250.5]
    lon = [[4 + 0.01 * j + 0.003 * i + 0.001 * rng.random() for j in range(5)] for i in range(4)]
    lat = [[52 - 0.01 * i + 0.002 * j + 0.001 * rng.random() for j in range(5)] for i in range(4)]
    ties = [
        v
        for i, r in enumerate(rows)
        for j, c in enumerate(cols)
        for v in (c, r, 0.0, lon[i][j], lat[i][j], 0.0)
    ]
    order = rng.permutation(len(ties) // 6)  # tie points in any order
    ties = np.asarray(ties).reshape(-1, 6)[order].ravel().tolist()
    path = _write(
        tmp_path / "gcp.tif", [(33922, "d", ties), (34735, "H", GEOGRAPHIC_KEYS)], shape=(300, 251)
    )
    pr = rng.uniform(-5, 305, 400)  # inside the grid and past its edges
    pc = rng.uniform(-5, 255, 400)
    with open_scene(path) as scene:
        assert isinstance(scene.georef, TiePointGrid)
        got_lon, got_lat = scene.georef.pixel_to_lonlat(pr, pc)
    for k in range(len(pr)):
        ref = _bilinear_reference(rows, cols, lon, lat, pr[k] + 0.5, pc[k] + 0.5)
        assert math.isclose(got_lon[k], ref[0], abs_tol=1e-10)
        assert math.isclose(got_lat[k], ref[1], abs_tol=1e-10)
    # at the nodes the grid gives the tie points back
    nodes_lon, nodes_lat = scene.georef.pixel_to_lonlat(np.array(rows) - 0.5, cols[1] - 0.5)
    np.testing.assert_allclose(nodes_lon, [lon[i][1] for i in range(4)], atol=1e-12)
    np.testing.assert_allclose(nodes_lat, [lat[i][1] for i in range(4)], atol=1e-12)


def test_tie_point_grid_across_the_antimeridian():
    g = TiePointGrid.from_points(
        [0, 0, 10, 10],
        [0, 10, 0, 10],
        [179.9, -179.9, 179.9, -179.9],
        [1, 1, 0, 0],
        pixel_is_point=True,
    )
    lon, lat = g.pixel_to_lonlat([5, 5], [5, 2.5])
    np.testing.assert_allclose(lon, [-180.0, 179.95], atol=1e-9)
    np.testing.assert_allclose(lat, [0.5, 0.5])


def test_tie_points_that_are_not_a_grid_are_refused(tmp_path):
    with pytest.raises(GeorefError, match="grid"):
        TiePointGrid.from_points([0, 0, 10, 11], [0, 10, 0, 10], [0, 1, 0, 1], [0, 0, 1, 1])
    with pytest.raises(GeorefError, match="repeat"):
        TiePointGrid.from_points([0, 0, 10, 10], [0, 0, 0, 10], [0, 1, 0, 1], [0, 0, 1, 1])
    ties = [0, 0, 0, 1, 1, 0, 9, 0, 0, 2, 1, 0, 0, 9, 0, 1, 2, 0, 5, 5, 0, 3, 3, 0]
    path = _write(tmp_path / "bad.tif", [(33922, "d", ties), (34735, "H", GEOGRAPHIC_KEYS)])
    from torchsar.io import FileFormatError

    with pytest.raises(FileFormatError, match="georeferencing"):
        open_scene(path)


def test_pixel_coordinates_must_be_finite():
    g = AffineGeoref((1.0, 0.0, 0.0, 0.0, -1.0, 0.0), epsg=4326, geographic=True)
    with pytest.raises(GeorefError, match="rows"):
        g.pixel_to_lonlat([np.nan], [0.0])
    with pytest.raises(GeorefError, match="cols"):
        g.pixel_to_lonlat([0.0], [1j])
    lon, lat = g.pixel_to_lonlat(np.zeros((0,)), np.zeros((0,)))
    assert lon.shape == lat.shape == (0,)


def test_ground_spacing_of_a_degree_grid_by_haversine():
    # 1e-4 degree pixels at latitude 60: along a meridian 11.119 m, along a parallel half
    g = AffineGeoref((1e-4, 0.0, 0.0, 0.0, -1e-4, 60.05), epsg=4326, geographic=True)
    row_m, col_m = ground_spacing(g, (1000, 1000))
    deg = 2 * math.pi * 6_371_008.8 / 360 * 1e-4
    assert math.isclose(row_m, deg, rel_tol=1e-6)
    assert math.isclose(col_m, deg * math.cos(math.radians(60.0)), rel_tol=1e-3)


def test_no_geotags_means_no_georef(tmp_path):
    path = tmp_path / "plain.tif"
    tifffile.imwrite(path, np.zeros((8, 8), np.uint8))
    with open_scene(path) as scene:
        assert scene.georef is None and scene.pixel_spacing is None
