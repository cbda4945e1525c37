"""Pixel spacing of a GeoTIFF, from its ModelPixelScale and GeoKey directory tags.

Only a projected model (``GTModelTypeGeoKey`` = 1) in metres (``ProjLinearUnitsGeoKey``
9001, or absent) gives a spacing; geographic (degree) grids and other units give ``None``.

Reference: OGC GeoTIFF standard 1.1 (tags 33550 ModelPixelScale, 34735 GeoKeyDirectory).
"""

from __future__ import annotations

from pathlib import Path

from torchsar.io.errors import FileFormatError
from torchsar.io.georef import geokeys
from torchsar.io.raster import check_regular_file, tifffile_log

__all__ = ["geotiff_pixel_spacing", "spacing_from_tags"]

MODEL_PIXEL_SCALE, GEO_KEY_DIRECTORY = 33550, 34735
MODEL_TYPE, LINEAR_UNITS = 1024, 3076
PROJECTED, METRE = 1, 9001


def geotiff_pixel_spacing(path: str | Path) -> tuple[float, float] | None:
    """``(row_m, col_m)`` from a projected, metre-based GeoTIFF, else ``None``.

    Raises:
        FileFormatError: not a regular file or an unreadable TIFF header.
    """
    check_regular_file(path)
    import tifffile

    with tifffile_log() as messages:
        try:
            with tifffile.TiffFile(path) as tif:
                tags = tif.pages[0].tags
                scale = tags.get(MODEL_PIXEL_SCALE)
                keys = tags.get(GEO_KEY_DIRECTORY)
                scale, keys = scale and scale.value, keys and keys.value
        except Exception as exc:  # any decoder complaint: name the file
            said = f"; tifffile: {'; '.join(messages[:3])}" if messages else ""
            raise FileFormatError(path, f"cannot read image header ({exc}{said})") from exc
    return spacing_from_tags(scale, keys)


def spacing_from_tags(scale: tuple | None, keys: tuple | None) -> tuple[float, float] | None:
    """``(row_m, col_m)`` from ModelPixelScale and GeoKeyDirectory tag values, or ``None``
    unless the model is projected in metres.

    Examples:
        >>> spacing_from_tags((0.75, 0.5, 0.0), (1, 1, 0, 1, 1024, 0, 1, 1))
        (0.5, 0.75)
    """
    if not scale or not keys:
        return None
    geo = geokeys(tuple(int(k) for k in keys))
    if geo.get(MODEL_TYPE) != PROJECTED or geo.get(LINEAR_UNITS, METRE) != METRE:
        return None
    col, row = float(scale[0]), float(scale[1])
    return (row, col) if row > 0 and col > 0 else None
