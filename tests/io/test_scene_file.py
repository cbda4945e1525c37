"""The big-scene fixture: written tile by tile, read back window by window.

The default run writes a 3000 x 2500 version; the full 30,000 x 25,000 scene is slow-marked.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tracemalloc

import numpy as np
import pandas as pd
import pytest
import tifffile

from torchsar.errors import OptionError
from torchsar.io import TiePointGrid, TiffScene, open_scene
from torchsar.simulate.scene_file import scene_lonlat, write_scene_file


def _check_targets(path, out, *, every: int = 1) -> None:
    """Each planted target is the brightest pixel of a window around it, with its amplitude
    and extent, and the clutter around it is far below."""
    t = pd.read_csv(out.targets_csv)
    pd.testing.assert_frame_equal(t, out.targets)
    with open_scene(path) as scene:
        assert scene.dtype == np.uint16 and scene.sample_type == "amplitude"
        for r, c, h, w, a in t.iloc[::every].itertuples(index=False):
            win = scene.read((r - 16, r + 16), (c - 16, c + 16))
            assert np.unravel_index(win.argmax(), win.shape) == (16, 16)
            assert win[16, 16] == a
            bright = np.argwhere(win >= a // 2)
            assert bright.min(0).tolist() == [16 - (h - 1) // 2, 16 - (w - 1) // 2]
            assert (bright.max(0) - bright.min(0) + 1).tolist() == [h, w]
            clutter = win[win < a // 2]
            assert clutter.max() < 15 * out.clutter_sigma


@pytest.fixture(scope="module")
def small_scene(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "small.tif"
    return path, write_scene_file(path, shape=(3000, 2500), n_targets=60, seed=7)


def test_small_scene_layout_and_targets(small_scene):
    path, out = small_scene
    with tifffile.TiffFile(path) as tif:
        page = tif.pages[0]
        assert tif.is_bigtiff and page.is_tiled and (page.tilelength, page.tilewidth) == (512, 512)
        assert page.compression == 8 and page.dtype == np.uint16  # deflate
    assert len(out.targets) == 60
    _check_targets(path, out)


def test_small_scene_windows_equal_full_read(small_scene):
    path, _ = small_scene
    full = tifffile.imread(path)
    rng = np.random.default_rng(0)
    with open_scene(path) as scene:
        for _ in range(10):
            r0, c0 = int(rng.integers(0, 3000 - 1024)), int(rng.integers(0, 2500 - 1024))
            np.testing.assert_array_equal(
                scene[r0 : r0 + 1024, c0 : c0 + 1024], full[r0 : r0 + 1024, c0 : c0 + 1024]
            )
        np.testing.assert_array_equal(scene[2900:3000, 2400:2500], full[2900:, 2400:])


def test_small_scene_georef_like_sentinel1(small_scene):
    path, out = small_scene
    with open_scene(path) as scene:
        assert isinstance(scene.georef, TiePointGrid)
        assert scene.georef.lon.shape == (10, 21)
        rows, cols = out.targets["row"].to_numpy(), out.targets["col"].to_numpy()
        lon, lat = scene.georef.pixel_to_lonlat(rows, cols)
        true_lon, true_lat = scene_lonlat(rows, cols)
        # bilinear over a 10 x 21 grid of a smooth mapping: within a metre on the ground
        assert np.abs(lat - true_lat).max() * 111_320 < 1.0
        assert np.abs(lon - true_lon).max() * 111_320 * np.cos(np.radians(52)) < 1.0
        assert np.allclose(scene.pixel_spacing, (10.0, 10.0), rtol=0.02)


def test_window_read_does_not_load_the_file(small_scene):
    path, _ = small_scene
    raw_bytes = 3000 * 2500 * 2
    with TiffScene(path, cache_mb=0) as scene:
        scene[0:8, 0:8]  # decoders built, header parsed
        tracemalloc.start()
        try:
            win = scene[1000:2024, 700:1724]
            _, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
    assert win.shape == (1024, 1024)
    # the window (2 MiB), the 9 compressed tiles it overlaps and one decoded 512 KiB tile
    # at a time: bounded by the window, well below the 15 MB image
    assert peak < 3 * win.nbytes < raw_bytes / 2, peak


def test_same_seed_same_file(tmp_path):
    a = write_scene_file(tmp_path / "a.tif", shape=(700, 600), tile=256, n_targets=4, seed=2)
    b = write_scene_file(tmp_path / "b.tif", shape=(700, 600), tile=256, n_targets=4, seed=2)
    np.testing.assert_array_equal(tifffile.imread(a.path), tifffile.imread(b.path))
    pd.testing.assert_frame_equal(a.targets, b.targets)


def test_scene_file_options_are_checked(tmp_path):
    for kwargs in (
        {"shape": (0, 10)},
        {"shape": (100,)},
        {"tile": 100},
        {"n_targets": -1},
        {"clutter_sigma": 0},
        {"level": 12},
        {"pool": 0},
    ):
        with pytest.raises(OptionError):
            write_scene_file(tmp_path / "x.tif", **kwargs)
    with pytest.raises(OptionError, match="cannot place"):
        write_scene_file(tmp_path / "x.tif", shape=(100, 100), tile=64, n_targets=50)


_RSS_PROBE = """
import json, resource, sys
from torchsar.io import open_scene
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
with open_scene(sys.argv[1]) as scene:
    opened = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    w = scene[14000:15024, 12000:13024]
    after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"open_kib": opened - before, "read_kib": after - opened, "max": int(w.max())}))
"""


@pytest.mark.slow
def test_full_size_scene(tmp_path):
    path = tmp_path / "big.tif"
    out = write_scene_file(path, n_targets=300, seed=0)
    size = os.path.getsize(path)
    with open_scene(path) as scene:
        assert scene.shape == (30_000, 25_000)
    _check_targets(path, out)
    probe = subprocess.run(
        [sys.executable, "-c", _RSS_PROBE, str(path)],
        capture_output=True,
        text=True,
        check=True,
        cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))),
    )
    rss = json.loads(probe.stdout)
    # peak RSS grows by the window and a few tiles, not by the file (~size) or image (1.5 GB)
    assert (rss["open_kib"] + rss["read_kib"]) * 1024 < size / 20, (rss, size)
