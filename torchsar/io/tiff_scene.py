"""Windowed reading of (Geo)TIFF, BigTIFF and COG scenes: only the tiles or strips a window
overlaps are read from disk and decoded.

tifffile parses the header and decodes single segments (deflate, packbits and uncompressed
always; LZW, zstd, JPEG and others when the optional ``imagecodecs`` package is installed);
this module picks the segments a window needs, reads them in file order and assembles the
window. Uncompressed files stored contiguously are memory-mapped instead. Segments with
offset or byte count 0 (sparse files) read as 0.

Samples are returned as stored (native byte order): uint8/16/32, int8/16/32, float32/64,
complex64/128; complex-integer samples (SampleFormat 5, e.g. complex int16 SLC) become
complex64. Sentinel-1 GRD measurement files are recognised by their description and hold
amplitude; for other files ``sample_type`` says what the samples are.
"""

from __future__ import annotations

import math
import os
import threading
from collections import OrderedDict
from pathlib import Path

import numpy as np

from torchsar.io.errors import FileFormatError
from torchsar.io.georef import (
    GEO_KEY_DIRECTORY,
    MODEL_PIXEL_SCALE,
    MODEL_TIEPOINT,
    MODEL_TRANSFORMATION,
    GeorefError,
    georef_from_tags,
    ground_spacing,
)
from torchsar.io.geotiff import spacing_from_tags
from torchsar.io.raster import check_regular_file, tifffile_log
from torchsar.io.scene_reader import SceneReader

__all__ = ["TiffScene", "is_sentinel1_grd"]

_GEO_TAGS = (MODEL_PIXEL_SCALE, MODEL_TIEPOINT, MODEL_TRANSFORMATION, GEO_KEY_DIRECTORY)
_KINDS = "uifc"


def is_sentinel1_grd(description: str) -> bool:
    """Whether a TIFF ImageDescription names a Sentinel-1 GRD product (amplitude samples).

    Examples:
        >>> is_sentinel1_grd("Sentinel-1A IW GRD HR L1")
        True
    """
    return "sentinel-1" in description.lower() and "grd" in description.lower()


def _said(messages: list[str]) -> str:
    distinct = list(dict.fromkeys(messages))[:3]
    return f"; tifffile: {'; '.join(distinct)}" if distinct else ""


MAX_SEGMENT_BYTES = 256 << 20
"""The largest decoded compressed tile or strip a scene may declare (bytes): each is
inflated whole, so the bound holds the memory a compressed segment can ask for before it
is read (an uncompressed segment is as large on disk as in memory)."""


class TiffScene(SceneReader):
    """A TIFF scene read window by window.

    Args:
        path: the file (TIFF, BigTIFF, COG; the full-resolution image is read).
        band: which sample of a multi-sample image, or which full-resolution page of a
            multi-page file; ``None`` for a single-band file.
        sample_type: what the samples are (one of ``torchsar.io.SAMPLE_TYPES``); inferred for
            complex samples and Sentinel-1 GRD (amplitude), else ``None``.
        as_intensity: return float32 intensity windows (amplitude squared, ``|z|**2``...).
        memmap: memory-map uncompressed contiguous files (``False`` reads them by strips).
        cache_mb: keep up to this many MB of decoded tiles (least recently used dropped), so
            overlapping or neighbouring windows do not decode a tile twice; 0 disables.

    Raises:
        FileFormatError: not a TIFF, truncated, an unsupported layout or sample type.
        OptionError: a ``band`` the file does not have, or intensity without a sample type.

    Examples:
        >>> import tempfile, tifffile
        >>> path = tempfile.mkdtemp() + "/s.tif"
        >>> a = np.arange(60 * 80, dtype=np.uint16).reshape(60, 80)
        >>> tifffile.imwrite(path, a, tile=(16, 32), compression="zlib")
        >>> with TiffScene(path) as scene:
        ...     scene.shape, np.array_equal(scene[10:40, 30:70], a[10:40, 30:70])
        ((60, 80), True)
    """

    def __init__(
        self,
        path: str | Path,
        *,
        band: int | None = None,
        sample_type: str | None = None,
        as_intensity: bool = False,
        memmap: bool = True,
        cache_mb: float = 64,
    ) -> None:
        self.path = str(path)
        self._options = {
            "band": band,
            "sample_type": sample_type,
            "as_intensity": as_intensity,
            "memmap": memmap,
            "cache_mb": cache_mb,
        }
        self._cache: OrderedDict[int, np.ndarray] = OrderedDict()
        self._cache_bytes, self._cache_limit = 0, int(max(float(cache_mb), 0.0) * 1e6)
        self._lock = threading.Lock()
        self._tif = None
        self._memmap = None
        check_regular_file(path)
        self._open(band, memmap)
        self._set_intensity(as_intensity, sample_type)

    # -- opening ---------------------------------------------------------------------------

    def _open(self, band: int | None, memmap: bool) -> None:
        import tifffile

        with tifffile_log() as messages:
            try:
                self._tif = tifffile.TiffFile(self.path)
                pages = list(self._tif.pages)
            except Exception as exc:  # any parser complaint: name the file
                self.close()
                raise FileFormatError(
                    self.path, f"is not a readable TIFF ({exc}{_said(messages)})"
                ) from exc
        try:
            self._page, self._sample = self._choose(pages, band)
            self._layout()
            self._check_extent()
            self._metadata()
            if memmap and self._page.is_memmappable:
                self._memmap = self._map()
        except BaseException:
            self.close()
            raise

    def _choose(self, pages: list, band: int | None) -> tuple[object, int]:
        """The page to read and the sample within it."""
        from torchsar.errors import OptionError

        full = [p for p in pages if not (getattr(p, "subfiletype", 0) & 1)]
        if not full:
            raise FileFormatError(self.path, "holds no full-resolution image")
        page = full[0]
        samples = int(page.samplesperpixel)
        if band is not None and (not isinstance(band, int) or isinstance(band, bool)):
            raise OptionError(f"band must be an integer or None, got {band!r}")
        if samples > 1:
            if band is None or not 0 <= band < samples:
                raise OptionError(
                    f"band must be one of 0..{samples - 1}: {self.path} has {samples} "
                    f"samples per pixel, got band={band!r}"
                )
            return page, band
        same = [p for p in full if (p.imagelength, p.imagewidth) == self._hw(page)]
        if band is None or band == 0:
            return page, 0
        if not 0 <= band < len(same):
            raise OptionError(
                f"band must be one of 0..{len(same) - 1} (full-resolution pages of "
                f"{self.path}), got band={band!r}"
            )
        return same[band], 0

    @staticmethod
    def _hw(page: object) -> tuple[int, int]:
        return int(page.imagelength), int(page.imagewidth)

    def _layout(self) -> None:
        """Segment grid: tile (or strip) size, counts, and the first segment of our band."""
        p = self._page
        h, w = self._hw(p)
        if h == 0 or w == 0:
            raise FileFormatError(self.path, f"declares an empty {h}x{w} image")
        if int(getattr(p, "imagedepth", 1)) != 1:
            raise FileFormatError(self.path, "is a volume (ImageDepth > 1), not a 2-D scene")
        dtype = p.dtype
        if dtype is None or np.dtype(dtype).kind not in _KINDS or np.dtype(dtype).itemsize > 16:
            raise FileFormatError(
                self.path,
                f"has an unsupported sample type (SampleFormat {p.sampleformat}, "
                f"{p.bitspersample}-bit)",
            )
        self.shape = (h, w)
        self.raw_dtype = np.dtype(np.dtype(dtype).newbyteorder("="))
        if p.is_tiled:
            self._th, self._tw = int(p.tilelength), int(p.tilewidth)
        else:
            self._th, self._tw = min(int(p.rowsperstrip or h), h), w
        if self._th <= 0 or self._tw <= 0:
            raise FileFormatError(self.path, f"declares segments of {self._th}x{self._tw}")
        samples = int(p.samplesperpixel) if p.planarconfig != 2 else 1
        decoded = self._th * self._tw * samples * self.raw_dtype.itemsize
        if decoded > MAX_SEGMENT_BYTES and p.compression != 1:  # from the header, unread
            raise FileFormatError(
                self.path,
                f"declares {self._th}x{self._tw} segments of {decoded:,} bytes each, over the "
                f"limit of {MAX_SEGMENT_BYTES:,} (a tile or strip is decoded whole; a "
                "compressed one that inflates to gigabytes would exhaust memory)",
            )
        self._nty, self._ntx = math.ceil(h / self._th), math.ceil(w / self._tw)
        per_plane = self._nty * self._ntx
        planes = int(p.samplesperpixel) if p.planarconfig == 2 else 1
        self._contig = 0 if p.planarconfig == 2 else self._sample
        self._base = per_plane * self._sample if p.planarconfig == 2 else 0
        self._offsets = np.asarray(p.dataoffsets, np.int64)
        self._counts = np.asarray(p.databytecounts, np.int64)
        if len(self._offsets) != per_plane * planes or len(self._counts) != len(self._offsets):
            raise FileFormatError(
                self.path,
                f"has {len(self._offsets)} segment offsets and {len(self._counts)} byte "
                f"counts; its {h}x{w} image in {self._th}x{self._tw} segments needs "
                f"{per_plane * planes}",
            )

    def _check_extent(self) -> None:
        """Refuse segments that point past the end of the file (a truncated file)."""
        size = os.path.getsize(self.path)
        used = self._counts > 0
        if used.any():
            end = int((self._offsets[used] + self._counts[used]).max())
            if end > size or int(self._offsets[used].min()) < 0:
                raise FileFormatError(
                    self.path,
                    f"is truncated: its image data reach byte {end:,}, but the file has "
                    f"{size:,} bytes",
                )
        if self._page.compression == 1 and used.any():
            p = self._page
            stored = int(p.bitspersample) // 8  # complex int16: 4 bytes, not 8
            pixel = stored * (1 if p.planarconfig == 2 else p.samplesperpixel)
            rows = np.full(len(self._counts), self._th, np.int64)
            if not p.is_tiled:  # the last strip of each plane may be shorter
                rows[self._nty - 1 :: self._nty] = self.shape[0] - (self._nty - 1) * self._th
            short = used & (self._counts < rows * self._tw * pixel)
            if short.any():
                raise FileFormatError(
                    self.path,
                    f"has {int(short.sum())} uncompressed segments shorter than their "
                    "declared size",
                )

    def _metadata(self) -> None:
        """Georeference, pixel spacing and sample type from the tags."""
        tags = {code: self._page.tags.get(code) for code in _GEO_TAGS}
        values = {code: t.value for code, t in tags.items() if t is not None}
        try:
            self.georef = georef_from_tags(values)
        except GeorefError as exc:
            raise FileFormatError(self.path, f"has unusable georeferencing ({exc})") from exc
        spacing = spacing_from_tags(values.get(MODEL_PIXEL_SCALE), values.get(GEO_KEY_DIRECTORY))
        if spacing is None and self.georef is not None:
            spacing = ground_spacing(self.georef, self.shape)
        self.pixel_spacing = spacing
        self.description = str(self._page.description or "")
        if self.raw_dtype.kind == "c":
            self.sample_type = "complex"
        elif is_sentinel1_grd(self.description) and self.raw_dtype.kind in "ui":
            self.sample_type = "amplitude"

    def _map(self) -> np.ndarray:
        """A read-only memmap of a contiguous uncompressed image, band selected."""
        p = self._page
        h, w = self.shape
        s = int(p.samplesperpixel)
        shape = (h, w) if s == 1 else (s, h, w) if p.planarconfig == 2 else (h, w, s)
        dtype = np.dtype(self._tif.byteorder + self.raw_dtype.char)
        m = np.memmap(self.path, dtype=dtype, mode="r", offset=int(p.dataoffsets[0]), shape=shape)
        return m if s == 1 else m[self._sample] if p.planarconfig == 2 else m[..., self._sample]

    # -- reading ---------------------------------------------------------------------------

    def segments(self, r0: int, r1: int, c0: int, c1: int) -> list[int]:
        """Indices (into the file's offsets) of the tiles or strips a window overlaps.

        Examples:
            >>> import tempfile, tifffile
            >>> path = tempfile.mkdtemp() + "/s.tif"
            >>> tifffile.imwrite(path, np.zeros((64, 64), np.uint8), tile=(16, 16))
            >>> TiffScene(path).segments(10, 20, 0, 16)
            [0, 4]
        """
        if r0 >= r1 or c0 >= c1:
            return []
        ty = range(r0 // self._th, (r1 - 1) // self._th + 1)
        tx = range(c0 // self._tw, (c1 - 1) // self._tw + 1)
        return [self._base + y * self._ntx + x for y in ty for x in tx]

    def _read(self, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        if self._tif is None:
            raise ValueError(f"{self.path} is closed")
        if self._memmap is not None:
            return np.array(self._memmap[r0:r1, c0:c1], dtype=self.raw_dtype)
        out = np.empty((r1 - r0, c1 - c0), self.raw_dtype)
        wanted = self.segments(r0, r1, c0, c1)
        with self._lock:
            cached = {i: self._cache[i] for i in wanted if i in self._cache}
            for i in cached:
                self._cache.move_to_end(i)
        for i, seg in cached.items():
            self._copy(out, seg, i, (r0, r1, c0, c1))
        index = [i for i in wanted if i not in cached]
        if not index:
            return out
        offsets = [int(self._offsets[i]) for i in index]
        counts = [int(self._counts[i]) for i in index]
        with tifffile_log() as messages:
            for data, i in self._tif.filehandle.read_segments(offsets, counts, indices=index):
                seg = self._decode(data, i, messages)
                self._copy(out, seg, i, (r0, r1, c0, c1))
                self._remember(i, seg)
        return out

    def _origin(self, i: int) -> tuple[int, int]:
        ty, tx = divmod(i - self._base, self._ntx)
        return ty * self._th, tx * self._tw

    def _decode(self, data: bytes | None, i: int, messages: list[str]) -> np.ndarray:
        """Segment ``i`` as a 2-D array of our band, clipped to the image (0 if sparse)."""
        top, left = self._origin(i)
        rows = min(self._th, self.shape[0] - top)
        cols = min(self._tw, self.shape[1] - left)
        if data is None:
            return np.zeros((rows, cols), self.raw_dtype)
        try:
            seg = self._page.decode(data, i)[0]
            seg = seg.reshape(seg.shape[-3], seg.shape[-2], seg.shape[-1])
            if seg.shape[0] < rows or seg.shape[1] < cols:
                raise ValueError(f"decoded to {seg.shape[:2]}, short of {rows}x{cols}")
            return seg[:rows, :cols, self._contig]
        except Exception as exc:  # corrupt or short segment: name file and place
            raise FileFormatError(
                self.path,
                f"cannot decode segment {i} (rows {top}:{top + self._th}, cols "
                f"{left}:{left + self._tw}): {exc}{_said(messages)}",
            ) from exc

    def _copy(self, out: np.ndarray, seg: np.ndarray, i: int, box: tuple) -> None:
        """Copy the part of segment ``i`` that lies in the window ``box`` into ``out``."""
        r0, r1, c0, c1 = box
        top, left = self._origin(i)
        rs, re = max(r0, top), min(r1, top + seg.shape[0])
        cs, ce = max(c0, left), min(c1, left + seg.shape[1])
        out[rs - r0 : re - r0, cs - c0 : ce - c0] = seg[rs - top : re - top, cs - left : ce - left]

    def _remember(self, i: int, seg: np.ndarray) -> None:
        """Keep a decoded segment, dropping the least recently used past the limit."""
        if seg.nbytes > self._cache_limit:
            return
        seg = np.ascontiguousarray(seg)
        with self._lock:
            if i in self._cache:
                return
            self._cache[i] = seg
            self._cache_bytes += seg.nbytes
            while self._cache_bytes > self._cache_limit:
                _, old = self._cache.popitem(last=False)
                self._cache_bytes -= old.nbytes

    # -- life cycle ------------------------------------------------------------------------

    def _close(self) -> None:
        self._memmap = None
        if hasattr(self, "_cache"):
            self._cache.clear()
            self._cache_bytes = 0
        if self._tif is not None:
            self._tif.close()
            self._tif = None

    def __getstate__(self) -> dict:
        return {"path": self.path, "options": self._options}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["path"], **state["options"])
