"""SICD / NITF complex products through the optional ``sarpy`` package (``torchsar[sar]``).

Read-only, one chip at a time: ``region=(r0, c0, r1, c1)`` (end-exclusive) is read without
loading the whole product. The pixel spacing is the SICD ``Grid.Row.SS`` x ``Grid.Col.SS``.
:class:`SicdScene` is the same product as a scene reader (``scene[r0:r1, c0:c1]``), with
lon/lat of pixels by sarpy's image-to-ground projection onto the scene's reference height.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from torchsar.io.errors import FileFormatError
from torchsar.io.raster import DEFAULT_MAX_PIXELS, check_regular_file
from torchsar.io.scene_reader import SceneReader

__all__ = ["SicdChip", "SicdScene", "read_sicd", "sicd_shape"]


@dataclass(frozen=True)
class SicdChip:
    """A complex chip and its pixel spacing ``(row_m, col_m)`` (``None`` if not given)."""

    samples: np.ndarray
    pixel_spacing: tuple[float, float] | None


def _open(path: str | Path):
    """A sarpy reader for the product, or a clear error when sarpy is missing."""
    try:
        from sarpy.io.complex.converter import open_complex
    except ImportError as exc:
        raise ImportError(
            "reading SICD/NITF needs the optional sarpy package: pip install 'sarpy>=1.3'"
        ) from exc
    check_regular_file(path)
    try:
        return open_complex(str(path))
    except Exception as exc:  # sarpy raises many types for unreadable products
        raise FileFormatError(path, f"is not a readable SICD/NITF product ({exc})") from exc


def sicd_shape(path: str | Path) -> tuple[int, int]:
    """``(rows, cols)`` of the first image of the product (header only)."""
    rows, cols = _open(path).get_data_size_as_tuple()[0]
    return int(rows), int(cols)


def read_sicd(
    path: str | Path,
    *,
    region: tuple[int, int, int, int] | None = None,
    max_pixels: int = DEFAULT_MAX_PIXELS,
) -> SicdChip:
    """Read a complex chip (the whole image when ``region`` is ``None``).

    Raises:
        ImportError: sarpy is not installed.
        FileFormatError: unreadable product, a region outside the image, or over max_pixels.
    """
    reader = _open(path)
    rows, cols = (int(v) for v in reader.get_data_size_as_tuple()[0])
    r0, c0, r1, c1 = region if region is not None else (0, 0, rows, cols)
    if not (0 <= r0 < r1 <= rows and 0 <= c0 < c1 <= cols):
        raise FileFormatError(path, f"region {(r0, c0, r1, c1)} is outside the {rows}x{cols} image")
    if (r1 - r0) * (c1 - c0) > max_pixels:
        raise FileFormatError(path, f"region of {(r1 - r0) * (c1 - c0):,} pixels > max_pixels")
    samples = np.asarray(reader[r0:r1, c0:c1], dtype=np.complex64)
    return SicdChip(samples, _spacing(reader.get_sicds_as_tuple()[0]))


def _spacing(sicd: object) -> tuple[float, float] | None:
    """``Grid.Row.SS`` x ``Grid.Col.SS`` of a SICD structure, or ``None``."""
    grid = getattr(sicd, "Grid", None)
    try:
        return (float(grid.Row.SS), float(grid.Col.SS))
    except (AttributeError, TypeError):
        return None


class _SicdGeoref:
    """Lon/lat of SICD pixels by sarpy's projection to the scene reference point height."""

    has_lonlat = True
    geographic = True
    epsg = 4326

    def __init__(self, sicd: object) -> None:
        self._sicd = sicd

    def pixel_to_lonlat(self, rows: object, cols: object) -> tuple[np.ndarray, np.ndarray]:
        from sarpy.geometry.point_projection import image_to_ground_geo

        r, c = np.broadcast_arrays(np.asarray(rows, np.float64), np.asarray(cols, np.float64))
        points = np.stack([r.ravel(), c.ravel()], axis=-1)
        llh = np.asarray(image_to_ground_geo(points, self._sicd), np.float64).reshape(-1, 3)
        return llh[:, 1].reshape(r.shape), llh[:, 0].reshape(r.shape)

    pixel_to_xy = pixel_to_lonlat


class SicdScene(SceneReader):
    """A SICD product read window by window (complex64 samples, ``sample_type="complex"``).

    Args:
        path: the NITF file.
        sample_type: ``"complex"`` or ``None``.
        as_intensity: return ``|z|**2`` as float32.

    Raises:
        ImportError: sarpy is not installed.
        FileFormatError: not a readable SICD product.
    """

    def __init__(
        self, path: str | Path, *, sample_type: str | None = None, as_intensity: bool = False
    ) -> None:
        self.path = str(path)
        self._options = {"sample_type": sample_type, "as_intensity": as_intensity}
        self._reader = _open(path)
        rows, cols = (int(v) for v in self._reader.get_data_size_as_tuple()[0])
        self.shape = (rows, cols)
        self.raw_dtype = np.dtype(np.complex64)
        self.sample_type = "complex"
        sicd = self._reader.get_sicds_as_tuple()[0]
        self.pixel_spacing = _spacing(sicd)
        self.georef = _SicdGeoref(sicd)
        self._set_intensity(as_intensity, sample_type)

    def _read(self, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        if self._reader is None:
            raise ValueError(f"{self.path} is closed")
        if r0 == r1 or c0 == c1:
            return np.empty((r1 - r0, c1 - c0), np.complex64)
        return np.asarray(self._reader[r0:r1, c0:c1], dtype=np.complex64)

    def _close(self) -> None:
        reader, self._reader = getattr(self, "_reader", None), None
        if reader is not None and hasattr(reader, "close"):
            reader.close()

    def __getstate__(self) -> dict:
        return {"path": self.path, "options": self._options}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["path"], **state["options"])
