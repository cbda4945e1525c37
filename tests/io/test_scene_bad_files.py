"""Files a scene reader must refuse with one clear FileFormatError naming the file."""

from __future__ import annotations

import os
import struct

import numpy as np
import pytest
import tifffile

from tests.io.scene_writers import scene_array
from torchsar.io import FileFormatError, open_scene


def _tiled(path, **kwargs):
    tifffile.imwrite(path, scene_array((256, 256), "uint16", seed=1), tile=(64, 64), **kwargs)
    return path


@pytest.mark.parametrize("compression", [None, "zlib"])
def test_truncated_data(tmp_path, compression):
    path = _tiled(tmp_path / "t.tif", compression=compression)
    size = os.path.getsize(path)
    with open(path, "r+b") as f:
        f.truncate(size - 1000)
    with pytest.raises(FileFormatError, match="truncated") as info:
        open_scene(path)
    assert info.value.path == str(path)


def test_truncated_header(tmp_path):
    path = _tiled(tmp_path / "t.tif")
    with open(path, "r+b") as f:
        f.truncate(12)
    with pytest.raises(FileFormatError, match="not a readable TIFF"):
        open_scene(path)


def test_not_a_tiff_and_empty_and_folder(tmp_path):
    (tmp_path / "x.tif").write_bytes(b"PNG but not really" * 10)
    (tmp_path / "empty.tif").write_bytes(b"")
    with pytest.raises(FileFormatError, match="neither a TIFF"):
        open_scene(tmp_path / "x.tif")
    with pytest.raises(FileFormatError, match="0 bytes"):
        open_scene(tmp_path / "empty.tif")
    with pytest.raises(FileFormatError, match="not a regular file"):
        open_scene(tmp_path)
    with pytest.raises(FileFormatError, match="cannot be read"):
        open_scene(tmp_path / "missing.tif")


def _patch_short(path, tag: int, value: int) -> None:
    """Overwrite a SHORT/LONG image-size tag of a classic TIFF with ``value``."""
    with tifffile.TiffFile(path, mode="r+b") as tif:
        tif.pages[0].tags[tag].overwrite(value)


def test_absurd_dimensions(tmp_path):
    path = _tiled(tmp_path / "huge.tif", compression="zlib")
    _patch_short(path, 256, 4_000_000_000)  # ImageWidth
    _patch_short(path, 257, 3_000_000_000)  # ImageLength
    with pytest.raises(FileFormatError, match="segment offsets|not a readable"):
        open_scene(path)


def test_empty_image(tmp_path):
    path = tmp_path / "zero.tif"
    # a hand-built little-endian TIFF: one IFD declaring a 0 x 5 uint8 image
    entries = [
        (256, 3, 1, 5),
        (257, 3, 1, 0),
        (258, 3, 1, 8),
        (273, 4, 1, 8),
        (277, 3, 1, 1),
        (278, 3, 1, 1),
        (279, 4, 1, 0),
    ]
    ifd = struct.pack("<H", len(entries))
    ifd += b"".join(struct.pack("<HHII", *e) for e in entries) + struct.pack("<I", 0)
    path.write_bytes(b"II*\x00" + struct.pack("<I", 8) + ifd)
    with pytest.raises(FileFormatError):
        open_scene(path)


def test_corrupt_tile_names_file_and_segment(tmp_path):
    path = _tiled(tmp_path / "c.tif", compression="zlib")
    with tifffile.TiffFile(path) as tif:
        offset = tif.pages[0].dataoffsets[5]
    with open(path, "r+b") as f:
        f.seek(offset)
        f.write(b"\x00" * 16)
    with open_scene(path) as scene:
        expected = scene_array((256, 256), "uint16", seed=1)
        np.testing.assert_array_equal(scene[0:64, 0:64], expected[:64, :64])
        with pytest.raises(FileFormatError, match=r"segment 5 \(rows 64:128, cols 64:128\)"):
            scene[60:70, 60:70]


def test_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "pipe.tif"
    os.mkfifo(fifo)
    with pytest.raises(FileFormatError, match="not a regular file"):
        open_scene(fifo)
