"""Raster reading: formats, header-first size limit, special files, truncated files,
channel agreement and palette indices."""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest

import torchsar.io.raster as raster
from tests.io.writers import write_png, write_tiff
from torchsar.io import FileFormatError, raster_shape, read_raster, single_channel

rng = np.random.default_rng(0)


@pytest.mark.parametrize(
    ("name", "a"),
    [
        ("f.tif", rng.random((5, 7)).astype(np.float32)),
        ("u.tif", rng.integers(0, 65535, (5, 7)).astype(np.uint16)),
        ("c.tif", (rng.random((5, 7)) + 1j * rng.random((5, 7))).astype(np.complex64)),
        ("iq.tif", rng.random((5, 7, 2)).astype(np.float32)),
        ("g.png", rng.integers(0, 255, (5, 7)).astype(np.uint8)),
        ("g16.png", rng.integers(0, 65535, (5, 7)).astype(np.uint16)),
        ("rgb.png", rng.integers(0, 255, (5, 7, 3)).astype(np.uint8)),
    ],
)
def test_round_trip_keeps_dtype_and_values(tmp_path, name, a):
    path = tmp_path / name
    (write_tiff if name.endswith(".tif") else write_png)(path, a)
    assert raster_shape(path) == a.shape
    out = read_raster(path)
    assert out.dtype == a.dtype
    np.testing.assert_array_equal(out, a)


def test_planar_two_channel_tiff_is_channels_last(tmp_path):
    a = rng.random((2, 5, 7)).astype(np.float32)
    path = write_tiff(tmp_path / "planar.tif", a)
    assert raster_shape(path) == (5, 7, 2)
    np.testing.assert_array_equal(read_raster(path), np.moveaxis(a, 0, -1))


def test_palette_png_is_read_by_index(tmp_path):
    labels = np.array([[0, 1, 2], [2, 1, 0]])
    path = write_png(tmp_path / "p.png", labels, palette=True)
    np.testing.assert_array_equal(read_raster(path), labels)


def test_size_limit_is_checked_before_decoding(tmp_path, monkeypatch):
    path = write_png(tmp_path / "big.png", np.zeros((40, 50), np.uint8))
    monkeypatch.setattr(raster, "_decode", lambda p: pytest.fail("decoded a refused image"))
    with pytest.raises(FileFormatError, match=r"big.png: is 50x40 = 2,000 pixels, over the limit"):
        read_raster(path, max_pixels=1999)


def test_fifo_is_refused_without_opening(tmp_path):
    fifo = tmp_path / "pipe.png"
    os.mkfifo(fifo)
    result = {}
    worker = threading.Thread(target=lambda: result.update(e=_error(fifo)), daemon=True)
    worker.start()
    worker.join(5)
    assert not worker.is_alive(), "reading a FIFO blocked"
    assert "pipe.png: is not a regular file" in result["e"]


def _error(path) -> str:
    try:
        read_raster(path)
    except FileFormatError as exc:
        return str(exc)
    return ""


@pytest.mark.parametrize("name", ["t.tif", "t.png"])
def test_truncated_file_names_the_file(tmp_path, name):
    path = tmp_path / name
    a = rng.random((64, 64)).astype(np.float32) if name.endswith("tif") else np.zeros((64, 64))
    (write_tiff if name.endswith(".tif") else write_png)(path, a)
    path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    with pytest.raises(FileFormatError, match=name):
        read_raster(path)


def test_missing_file_names_it(tmp_path):
    with pytest.raises(FileFormatError, match="nope.png: cannot be read"):
        read_raster(tmp_path / "nope.png")


def test_grey_saved_as_rgb_is_accepted_colour_refused():
    grey = rng.integers(0, 3, (4, 5))
    np.testing.assert_array_equal(single_channel(np.dstack([grey] * 3), "m.png"), grey)
    np.testing.assert_array_equal(single_channel(np.dstack([grey, grey * 0 + 255]), "m.png"), grey)
    red_only = np.dstack([grey, grey * 0, grey * 0])
    with pytest.raises(FileFormatError, match=r"m.png: has 3 channels that differ at \d+ pixels"):
        single_channel(red_only, "m.png")
    assert single_channel(np.dstack([grey, grey, grey + 2]), "j.jpeg", tolerance=2) is not None
