"""Windows of TiffScene equal the same window of a full tifffile.imread, in every layout."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import tifffile

from tests.io.scene_writers import scene_array, windows, write_complex_int16
from torchsar.errors import OptionError, WindowSizeError
from torchsar.io import FileFormatError, TiffScene, WindowError, open_scene

SHAPE = (203, 171)  # not a multiple of any tile: partial tiles at both edges

LAYOUTS = {
    "tiled-deflate": {"tile": (32, 48), "compression": "zlib"},
    "tiled-raw": {"tile": (32, 48)},
    "striped-deflate": {"rowsperstrip": 7, "compression": "zlib"},
    "striped-raw": {"rowsperstrip": 7},
    "one-strip-raw": {},
    "tiled-deflate-predictor": {"tile": (64, 64), "compression": "zlib", "predictor": True},
    "tiled-packbits": {"tile": (16, 16), "compression": "packbits"},
    "bigtiff-tiled-deflate": {"tile": (32, 32), "compression": "zlib", "bigtiff": True},
    "bigtiff-striped-raw": {"rowsperstrip": 50, "bigtiff": True},
    "big-endian-tiled": {"tile": (32, 32), "compression": "zlib", "byteorder": ">"},
    "big-endian-raw": {"byteorder": ">"},
}


try:
    import imagecodecs  # noqa: F401

    HAVE_CODECS = True
except ImportError:
    HAVE_CODECS = False


def _check_all_windows(path, expected, tile, **options):
    with open_scene(path, **options) as scene:
        assert scene.shape == expected.shape[:2]
        for r0, r1, c0, c1 in windows(expected.shape[:2], tile, 12, seed=r0_seed(path)):
            got = scene[r0:r1, c0:c1]
            assert got.dtype == scene.dtype
            np.testing.assert_array_equal(got, expected[r0:r1, c0:c1])


def r0_seed(path) -> int:
    return sum(map(ord, str(path.name)))


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
@pytest.mark.parametrize("dtype", ["uint8", "uint16", "float32", "complex64"])
def test_windows_equal_full_read(tmp_path, layout, dtype):
    options = dict(LAYOUTS[layout])
    if dtype == "complex64" and options.get("predictor"):
        pytest.skip("no predictor for complex samples")
    if not HAVE_CODECS and (
        "packbits" in layout or (dtype == "float32" and options.get("predictor"))
    ):
        pytest.skip("writing PackBits or a floating-point predictor needs imagecodecs")
    a = scene_array(SHAPE, dtype, seed=len(layout))
    path = tmp_path / f"{layout}-{dtype}.tif"
    tifffile.imwrite(path, a, photometric="minisblack", **options)
    full = tifffile.imread(path)
    np.testing.assert_array_equal(full, a)
    tile = options.get("tile", (options.get("rowsperstrip", SHAPE[0]), SHAPE[1]))
    _check_all_windows(path, full, tile)


def test_memmap_and_strip_reads_agree(tmp_path):
    a = scene_array(SHAPE, "float32", seed=3)
    path = tmp_path / "raw.tif"
    tifffile.imwrite(path, a, rowsperstrip=16)
    mapped, decoded = TiffScene(path), TiffScene(path, memmap=False)
    assert mapped._memmap is not None and decoded._memmap is None
    for r0, r1, c0, c1 in windows(SHAPE, (16, SHAPE[1]), 8, seed=1):
        np.testing.assert_array_equal(mapped[r0:r1, c0:c1], decoded[r0:r1, c0:c1])


def test_complex_int16(tmp_path):
    rng = np.random.default_rng(5)
    re, im = (rng.integers(-32768, 32767, size=SHAPE, dtype=np.int16) for _ in range(2))
    path = write_complex_int16(tmp_path / "slc.tif", re, im, tile=(32, 32))
    expected = re.astype(np.float32) + 1j * im.astype(np.float32)
    with open_scene(path) as scene:
        assert scene.dtype == np.complex64 and scene.sample_type == "complex"
        np.testing.assert_array_equal(scene[40:120, 10:170], expected[40:120, 10:170])
    with open_scene(path, as_intensity=True) as scene:
        w = scene[0:50, 0:50]
        ref = re[:50, :50].astype(np.float64) ** 2 + im[:50, :50].astype(np.float64) ** 2
        np.testing.assert_allclose(w, ref, rtol=1e-6)


@pytest.mark.parametrize("planar", ["contig", "separate"])
def test_band_of_multi_sample_image(tmp_path, planar):
    bands = np.stack([scene_array(SHAPE, "uint16", seed=s) for s in range(3)])
    data = bands if planar == "separate" else np.moveaxis(bands, 0, -1)
    path = tmp_path / "rgb.tif"
    tifffile.imwrite(
        path, data, tile=(32, 32), compression="zlib", photometric="rgb", planarconfig=planar
    )
    for b in range(3):
        with open_scene(path, band=b) as scene:
            np.testing.assert_array_equal(scene[17:150, 33:160], bands[b, 17:150, 33:160])
    with pytest.raises(OptionError, match="band"):
        open_scene(path)
    with pytest.raises(OptionError, match="band"):
        open_scene(path, band=3)


def test_band_as_page_of_multi_page_file(tmp_path):
    pages = [scene_array(SHAPE, "float32", seed=s) for s in range(2)]
    path = tmp_path / "pages.tif"
    with tifffile.TiffWriter(path) as tw:
        for p in pages:
            tw.write(p, tile=(32, 32), compression="zlib", photometric="minisblack")
    for b in range(2):
        with open_scene(path, band=b) as scene:
            np.testing.assert_array_equal(scene[5:200, 0:100], pages[b][5:200, 0:100])
    with pytest.raises(OptionError, match="band"):
        open_scene(path, band=2)


def test_only_overlapping_tiles_are_read(tmp_path):
    """Overwrite every tile the window does not touch with garbage: the window still reads
    right (and the full read fails), so no other tile was decoded."""
    a = scene_array((256, 256), "uint16", seed=8)
    path = tmp_path / "t.tif"
    tifffile.imwrite(path, a, tile=(64, 64), compression="zlib")
    scene = TiffScene(path)
    keep = set(scene.segments(70, 130, 60, 140))
    assert keep == {4 * ty + tx for ty in (1, 2) for tx in (0, 1, 2)}
    with tifffile.TiffFile(path) as tif:
        offsets, counts = tif.pages[0].dataoffsets, tif.pages[0].databytecounts
    scene.close()
    with open(path, "r+b") as f:
        for i, (o, n) in enumerate(zip(offsets, counts, strict=True)):
            if i not in keep:
                f.seek(o)
                f.write(b"\xff" * n)
    with open_scene(path) as scene:
        np.testing.assert_array_equal(scene[70:130, 60:140], a[70:130, 60:140])
        with pytest.raises(FileFormatError, match="segment 0"):
            scene[0:10, 0:10]


def test_sparse_tiles_read_as_zero(tmp_path):
    a = scene_array((128, 128), "uint8", seed=2)
    path = tmp_path / "sparse.tif"
    tifffile.imwrite(path, a, tile=(64, 64), compression="zlib")
    with tifffile.TiffFile(path, mode="r+b") as tif:
        offsets = list(tif.pages[0].dataoffsets)
        counts = list(tif.pages[0].databytecounts)
        offsets[3], counts[3] = 0, 0
        tif.pages[0].tags[324].overwrite(offsets)
        tif.pages[0].tags[325].overwrite(counts)
    expected = a.copy()
    expected[64:, 64:] = 0
    with open_scene(path) as scene:
        np.testing.assert_array_equal(scene[:, :], expected)


def test_window_errors_name_the_argument(tmp_path):
    path = tmp_path / "s.tif"
    tifffile.imwrite(path, np.zeros((50, 40), np.float32), tile=(16, 16))
    scene = open_scene(path)
    bad = [
        (slice(0, 51), slice(0, 10)),
        (slice(-1, 10), slice(0, 10)),
        (slice(0, 10), slice(30, 41)),
        (slice(0, 10, 2), slice(0, 10)),
        (slice(5, 2), slice(0, 10)),
        (slice(0, 10),),
        (0, slice(0, 10)),
        (slice(0.5, 10), slice(0, 10)),
    ]
    for window in bad:
        with pytest.raises(WindowError, match="window") as info:
            scene[window]
        assert isinstance(info.value, WindowSizeError) and isinstance(info.value, IndexError)
    assert scene[3:3, 0:10].shape == (0, 10)  # an empty window is valid
    assert scene[np.int64(2) : np.int64(4), :].shape == (2, 40)


def test_read_pads_outside_with_fill(tmp_path):
    a = scene_array((50, 40), "float32", seed=4)
    path = tmp_path / "s.tif"
    tifffile.imwrite(path, a, tile=(16, 16), compression="zlib")
    with open_scene(path) as scene:
        got = scene.read((-5, 10), (35, 47), fill=-1.0)
    expected = np.full((15, 12), -1.0, np.float32)
    expected[5:, :5] = a[:10, 35:]
    np.testing.assert_array_equal(got, expected)
    with open_scene(path) as scene:
        assert (scene.read((60, 70), (0, 4), fill=7) == 7).all()
        with pytest.raises(WindowError, match="rows"):
            scene.read((10, 5), (0, 4))


def test_intensity_options(tmp_path):
    amp = scene_array((40, 30), "uint16", seed=6)
    path = tmp_path / "amp.tif"
    tifffile.imwrite(path, amp, tile=(16, 16))
    with pytest.raises(OptionError, match="sample_type"):
        open_scene(path, as_intensity=True)
    with pytest.raises(OptionError, match="sample_type"):
        open_scene(path, sample_type="complex")
    with open_scene(path, sample_type="amplitude", as_intensity=True) as scene:
        assert scene.dtype == np.float32
        np.testing.assert_allclose(scene[:, :], amp.astype(np.float64) ** 2, rtol=1e-6)
    with open_scene(path, sample_type="amplitude") as scene:  # raw unless asked
        assert scene.dtype == np.uint16 and scene.sample_type == "amplitude"
    s1 = tmp_path / "s1.tif"
    tifffile.imwrite(s1, amp, tile=(16, 16), description="Sentinel-1B IW GRD HR L1")
    with open_scene(s1, as_intensity=True) as scene:
        assert scene.sample_type == "amplitude"
        np.testing.assert_allclose(scene[0:4, 0:4], amp[:4, :4].astype(np.float64) ** 2)


def test_pickles_by_path_and_closes(tmp_path):
    a = scene_array((64, 64), "uint16", seed=1)
    path = tmp_path / "s.tif"
    tifffile.imwrite(path, a, tile=(32, 32), compression="zlib")
    scene = open_scene(path, sample_type="amplitude", as_intensity=True)
    clone = pickle.loads(pickle.dumps(scene))
    np.testing.assert_array_equal(clone[10:50, 3:60], scene[10:50, 3:60])
    assert clone.intensity and clone.dtype == np.float32
    scene.close()
    scene.close()
    with pytest.raises(ValueError, match="closed"):
        scene[0:1, 0:1]


@pytest.mark.skipif(not HAVE_CODECS, reason="LZW and zstd need imagecodecs")
def test_lzw_and_zstd_when_imagecodecs_is_installed(tmp_path):
    a = scene_array(SHAPE, "uint16", seed=9)
    for compression in ("lzw", "zstd"):
        path = tmp_path / f"{compression}.tif"
        tifffile.imwrite(path, a, tile=(32, 32), compression=compression)
        _check_all_windows(path, a, (32, 32))


@pytest.mark.skipif(HAVE_CODECS, reason="imagecodecs installed: LZW decodes")
def test_unsupported_codec_is_a_clear_error(tmp_path):
    a = scene_array((64, 64), "uint16", seed=9)
    path = tmp_path / "lzw.tif"
    tifffile.imwrite(path, a, tile=(32, 32), compression="zlib")
    with tifffile.TiffFile(path, mode="r+b") as tif:
        tif.pages[0].tags[259].overwrite(5)  # claim LZW
    with open_scene(path) as scene, pytest.raises(FileFormatError, match="segment"):
        scene[0:4, 0:4]


def test_tile_cache_is_bounded_and_changes_nothing(tmp_path):
    a = scene_array((300, 300), "uint16", seed=12)
    path = tmp_path / "c.tif"
    tifffile.imwrite(path, a, tile=(32, 32), compression="zlib")
    tile_bytes = 32 * 32 * 2
    plain = TiffScene(path, cache_mb=0)
    small = TiffScene(path, cache_mb=5.5 * tile_bytes / 1e6)
    for r0, r1, c0, c1 in windows((300, 300), (32, 32), 30, seed=4) * 2:
        expected = a[r0:r1, c0:c1]
        np.testing.assert_array_equal(plain[r0:r1, c0:c1], expected)
        np.testing.assert_array_equal(small[r0:r1, c0:c1], expected)
        assert 0 < small._cache_bytes <= 5.5 * tile_bytes
    assert not plain._cache


def test_a_compressed_tile_that_would_inflate_to_gigabytes_is_refused(tmp_path):
    """A small file whose header declares 32768 x 32768 float32 tiles (4 GiB each once
    inflated): refused from the header, before any tile is decoded (before: detect ran to
    4.6 GB and exited 0)."""
    import tifffile

    from torchsar.io.tiff_scene import MAX_SEGMENT_BYTES

    path = tmp_path / "bomb.tif"
    tifffile.imwrite(
        path, np.zeros((256, 256), np.float32), tile=(256, 256), compression="zlib", bigtiff=True
    )
    with tifffile.TiffFile(path, mode="r+b") as tif:
        for code in (322, 323):  # TileWidth, TileLength
            tif.pages[0].tags[code].overwrite(32768)
    with pytest.raises(FileFormatError, match=f"over the limit of {MAX_SEGMENT_BYTES:,}"):
        open_scene(path, sample_type="intensity")
