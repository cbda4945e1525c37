"""SICD / NITF complex products through the optional ``sarpy`` package (``torchsar[sar]``).

Read-only, one chip at a time: ``region=(r0, c0, r1, c1)`` (end-exclusive) is read without
loading the whole product. The pixel spacing is the SICD ``Grid.Row.SS`` x ``Grid.Col.SS``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from torchsar.io.errors import FileFormatError
from torchsar.io.raster import DEFAULT_MAX_PIXELS, check_regular_file

__all__ = ["SicdChip", "read_sicd", "sicd_shape"]


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
    grid = getattr(reader.get_sicds_as_tuple()[0], "Grid", None)
    try:
        spacing = (float(grid.Row.SS), float(grid.Col.SS))
    except (AttributeError, TypeError):
        spacing = None
    return SicdChip(samples, spacing)
