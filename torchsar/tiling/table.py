"""The scene detection table: one row per detected object of a whole scene, in xView3-SAR
column names, written as CSV and GeoJSON.

Columns (:data:`DETECTION_COLUMNS`):

- ``scene_id``: the scene's name (a file's stem);
- ``detect_scene_row``, ``detect_scene_column``: the object's **peak**, the pixel of its
  highest detector statistic (integer array indices, ``(0, 0)`` the first pixel's centre;
  ties: first in raster order). The peak, not the centroid, because it is a pixel of the
  object whatever its shape, it is where a point target's energy is, and it is what point
  ground truth (xView3's ``detect_scene_row``/``column``, the planted targets of
  :func:`torchsar.simulate.scene_file.write_scene_file`) marks; the centroid is kept too;
- ``centroid_row``, ``centroid_col``: mean pixel coordinates (float);
- ``lon``, ``lat``: degrees at the peak pixel, when the scene is georeferenced and the
  mapping gives lon/lat; empty otherwise;
- ``score``: the detector's statistic at the peak;
- ``area_px``: pixels of the object;
- ``row_min``, ``row_max``, ``col_min``, ``col_max``: inclusive bounding box;
- ``length_m``: the larger side of the bounding box in metres,
  ``max((row_max - row_min + 1) * row_spacing, (col_max - col_min + 1) * col_spacing)``,
  with the scene's pixel spacing; empty without one. It is exact for an object aligned
  with the image axes and as low as ``1 / sqrt(2)`` of the length of a thin object at 45
  degrees (a CFAR mask also holds a ship's bright scatterers, not its outline).

Rows keep the order of the object table (score descending, then peak position), scenes
in the order given. The CSV is what ``torchsar-eval run --predictions NAME=FILE`` reads as
point predictions.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from torchsar.errors import OptionError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["DETECTION_COLUMNS", "detection_table", "write_csv", "write_geojson"]

DETECTION_COLUMNS = (
    "scene_id",
    "detect_scene_row",
    "detect_scene_column",
    "centroid_row",
    "centroid_col",
    "lon",
    "lat",
    "score",
    "area_px",
    "row_min",
    "row_max",
    "col_min",
    "col_max",
    "length_m",
)

_FLOATS = ("centroid_row", "centroid_col", "lon", "lat", "score", "length_m")


def _lonlat(georef: object, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """lon/lat of pixels, or NaN where the scene has no mapping to lon/lat."""
    nan = np.full(rows.shape, np.nan)
    if georef is None or rows.size == 0 or getattr(georef, "has_lonlat", True) is False:
        return nan, nan.copy()
    lon, lat = georef.pixel_to_lonlat(rows, cols)  # type: ignore[attr-defined]
    return np.asarray(lon, np.float64), np.asarray(lat, np.float64)


def _spacing(pixel_spacing: object) -> tuple[float, float] | None:
    if pixel_spacing is None:
        return None
    try:
        r, c = (float(v) for v in pixel_spacing)  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise OptionError(
            f"pixel_spacing must be (row_m, col_m) or None, got {pixel_spacing!r}"
        ) from None
    if not (0 < r < math.inf and 0 < c < math.inf):
        raise OptionError(f"pixel_spacing must be positive finite metres, got {pixel_spacing!r}")
    return r, c


def detection_table(
    objects: pd.DataFrame,
    scene_id: str,
    *,
    georef: object = None,
    pixel_spacing: Sequence[float] | None = None,
) -> pd.DataFrame:
    """The detection table of one scene from its object table.

    Args:
        objects: :func:`~torchsar.tiling.scene_objects` rows (``row``, ``col``,
            ``peak_row``, ``peak_col``, ``score``, ``area`` and the bounding box).
        scene_id: the scene's name, repeated on every row.
        georef: the scene reader's ``georef`` (``pixel_to_lonlat(rows, cols)``) or None.
        pixel_spacing: ``(row_m, col_m)`` or None (no ``length_m``).

    Returns:
        The columns of :data:`DETECTION_COLUMNS` (see the module docstring), same row order.

    Raises:
        OptionError: ``objects`` lacks a column, a bad ``pixel_spacing`` or ``scene_id``.

    Examples:
        >>> from torchsar.tiling import components_table
        >>> m = np.zeros((6, 8), bool); m[1:3, 2:6] = True
        >>> t = detection_table(components_table(m, m * 2.0), "s1", pixel_spacing=(10, 5))
        >>> r = t.iloc[0]
        >>> int(r.detect_scene_row), int(r.detect_scene_column), int(r.area_px), float(r.length_m)
        (1, 2, 8, 20.0)
        >>> bool(t["lat"].isna().all())
        True
    """
    from torchsar.tiling.objects import COLUMNS

    missing = [c for c in COLUMNS if c not in objects.columns]
    if missing:
        raise OptionError(f"objects lacks column(s) {', '.join(missing)} (an object table)")
    if not isinstance(scene_id, str) or not scene_id:
        raise OptionError(f"scene_id must be a non-empty string, got {scene_id!r}")
    spacing = _spacing(pixel_spacing)
    peak_r = objects["peak_row"].to_numpy(np.int64)
    peak_c = objects["peak_col"].to_numpy(np.int64)
    lon, lat = _lonlat(georef, peak_r, peak_c)
    box_h = (objects["row_max"] - objects["row_min"] + 1).to_numpy(np.float64)
    box_w = (objects["col_max"] - objects["col_min"] + 1).to_numpy(np.float64)
    if spacing is None:
        length = np.full(len(objects), np.nan)
    else:
        length = np.maximum(box_h * spacing[0], box_w * spacing[1])
    import pandas as pd  # here, not at import: torchsar loads without pandas

    out = pd.DataFrame(
        {
            "scene_id": pd.Series([scene_id] * len(objects), dtype=object),
            "detect_scene_row": peak_r,
            "detect_scene_column": peak_c,
            "centroid_row": objects["row"].to_numpy(np.float64),
            "centroid_col": objects["col"].to_numpy(np.float64),
            "lon": lon,
            "lat": lat,
            "score": objects["score"].to_numpy(np.float64),
            "area_px": objects["area"].to_numpy(np.int64),
            "row_min": objects["row_min"].to_numpy(np.int64),
            "row_max": objects["row_max"].to_numpy(np.int64),
            "col_min": objects["col_min"].to_numpy(np.int64),
            "col_max": objects["col_max"].to_numpy(np.int64),
            "length_m": length,
        }
    )
    return out[list(DETECTION_COLUMNS)]


def _check_table(table: pd.DataFrame) -> None:
    missing = [c for c in DETECTION_COLUMNS if c not in table.columns]
    if missing:
        raise OptionError(f"table lacks column(s) {', '.join(missing)} (a detection table)")


def write_csv(table: pd.DataFrame, path: str | Path) -> Path:
    """Write the table as CSV: a header of :data:`DETECTION_COLUMNS`, floats in their
    shortest round-trip form, unknown values (``lat``, ``lon``, ``length_m``) empty.
    The same table gives the same bytes."""
    _check_table(table)
    path = Path(path)
    table[list(DETECTION_COLUMNS)].to_csv(path, index=False, lineterminator="\n")
    return path


def _value(v: object) -> object:
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def write_geojson(table: pd.DataFrame, path: str | Path) -> Path:
    """Write the table as a GeoJSON FeatureCollection of points ``[lon, lat]`` whose
    properties are the columns (unknown values ``null``).

    Raises:
        OptionError: a row without lon/lat (the scene is not georeferenced: write the CSV
            only).
    """
    _check_table(table)
    lonlat = table[["lon", "lat"]].to_numpy(np.float64)
    if len(table) and not np.isfinite(lonlat).all():
        raise OptionError(
            "rows without lon/lat: the scene has no georeferencing to lon/lat, so there is "
            "no GeoJSON to write (the CSV holds the pixel positions)"
        )
    cols = list(DETECTION_COLUMNS)
    features = [
        {
            "type": "Feature",
            "geometry": {"type": "Point", "coordinates": [float(lon), float(lat)]},
            "properties": {c: _value(v) for c, v in zip(cols, row, strict=True)},
        }
        for (lon, lat), row in zip(lonlat, table[cols].itertuples(index=False), strict=True)
    ]
    doc = {"type": "FeatureCollection", "features": features}
    path = Path(path)
    path.write_text(json.dumps(doc, separators=(",", ":"), allow_nan=False) + "\n")
    return path
