"""Pixel-to-ground mappings of a scene: a GeoTIFF affine model or a grid of tie points.

Pixel coordinates are array indices: ``(row, col) = (0, 0)`` is the centre of the first
pixel, and fractional values are allowed. A GeoTIFF states whether its model refers to
pixel corners (``PixelIsArea``, the default: index ``i`` is raster coordinate ``i + 0.5``)
or to pixel centres (``PixelIsPoint``: raster coordinate ``i``); both are honoured here.

- :class:`AffineGeoref`: ``ModelTransformation``, or ``ModelPixelScale`` with a single
  ``ModelTiepoint``. Geographic models (``GTModelTypeGeoKey`` = 2) map straight to
  lon/lat. Projected models map to projected ``(x, y)`` in the CRS ``epsg``; lon/lat then
  needs the optional ``pyproj`` package, and without it :meth:`~AffineGeoref.pixel_to_lonlat`
  raises :class:`GeorefError` (``pixel_to_xy`` still works, ``has_lonlat`` says which).
- :class:`TiePointGrid`: many ``ModelTiepoint`` points on a rectilinear grid of rows and
  columns (Sentinel-1 GRD measurement files carry a grid of about 10 x 21 points),
  interpolated bilinearly per pixel cell and extrapolated linearly from the edge cells.
  Longitudes are unwrapped before interpolating, so a scene across the antimeridian
  interpolates through +-180 degrees, not across the globe.

Reference: OGC GeoTIFF standard 1.1 (tags 33550 ModelPixelScale, 33922 ModelTiepoint,
34264 ModelTransformation, 34735 GeoKeyDirectory; keys 1024 GTModelType, 1025
GTRasterType, 2048 GeographicType, 3072 ProjectedCSType).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from torchsar.errors import GeorefError

__all__ = [
    "AffineGeoref",
    "GeorefError",
    "TiePointGrid",
    "georef_from_tags",
    "ground_spacing",
]

MODEL_PIXEL_SCALE, MODEL_TIEPOINT, MODEL_TRANSFORMATION, GEO_KEY_DIRECTORY = (
    33550,
    33922,
    34264,
    34735,
)
MODEL_TYPE, RASTER_TYPE, GEOGRAPHIC_TYPE, PROJECTED_TYPE = 1024, 1025, 2048, 3072
PROJECTED, GEOGRAPHIC = 1, 2
PIXEL_IS_POINT = 2
EARTH_RADIUS_M = 6_371_008.8  # mean Earth radius (IUGG)


def geokeys(directory: tuple[int, ...] | None) -> dict[int, int]:
    """Short-valued keys of a GeoKeyDirectory (header of 4, then 4 shorts per key).

    Examples:
        >>> geokeys((1, 1, 0, 2, 1024, 0, 1, 2, 2048, 0, 1, 4326))
        {1024: 2, 2048: 4326}
    """
    if not directory or len(directory) < 4:
        return {}
    n = int(directory[3])
    entries = [int(v) for v in directory[4 : 4 + 4 * n]]
    return {
        entries[i]: entries[i + 3] for i in range(0, len(entries) - 3, 4) if entries[i + 1] == 0
    }


def _pixels(rows: object, cols: object) -> tuple[np.ndarray, np.ndarray]:
    """Broadcast float64 arrays of pixel indices, refusing NaN/Inf and complex."""
    r, c = np.asarray(rows), np.asarray(cols)
    for name, a in (("rows", r), ("cols", c)):
        if a.dtype.kind not in "biuf":
            raise GeorefError(f"{name} must be real numbers, got dtype {a.dtype}")
        if a.size and not np.isfinite(a).all():
            raise GeorefError(f"{name} contain NaN or Inf")
    r, c = np.broadcast_arrays(r.astype(np.float64), c.astype(np.float64))
    return r, c


@dataclass(frozen=True)
class AffineGeoref:
    """An affine pixel-to-model mapping ``x = a*col + b*row + c``, ``y = d*col + e*row + f``
    in raster coordinates (pixel corners), and its CRS.

    Attributes:
        coeffs: ``(a, b, c, d, e, f)``.
        epsg: EPSG code of the CRS (``None`` if the file does not say).
        geographic: ``x, y`` are lon/lat degrees (``True``) or projected units (``False``).
        pixel_is_point: the model refers to pixel centres (``PixelIsPoint``).

    Examples:
        >>> g = AffineGeoref((0.001, 0.0, 10.0, 0.0, -0.001, 50.0), epsg=4326, geographic=True)
        >>> [v.tolist() for v in g.pixel_to_lonlat([0, 999], [0, 0])]
        [[10.0005, 10.0005], [49.9995, 49.0005]]
    """

    coeffs: tuple[float, float, float, float, float, float]
    epsg: int | None = None
    geographic: bool = False
    pixel_is_point: bool = False

    @property
    def has_lonlat(self) -> bool:
        """Whether :meth:`pixel_to_lonlat` can answer (geographic, or pyproj installed)."""
        return self.geographic or (self.epsg is not None and _pyproj() is not None)

    def pixel_to_xy(self, rows: object, cols: object) -> tuple[np.ndarray, np.ndarray]:
        """Model coordinates ``(x, y)`` (lon/lat for a geographic CRS) of pixel indices."""
        r, c = _pixels(rows, cols)
        shift = 0.0 if self.pixel_is_point else 0.5
        a, b, c0, d, e, f = self.coeffs
        return a * (c + shift) + b * (r + shift) + c0, d * (c + shift) + e * (r + shift) + f

    def pixel_to_lonlat(self, rows: object, cols: object) -> tuple[np.ndarray, np.ndarray]:
        """``(lon, lat)`` in degrees of pixel indices (arrays broadcast together).

        Raises:
            GeorefError: a projected CRS without pyproj installed, or an unknown CRS
                (``pixel_to_xy`` gives the projected coordinates then).
        """
        x, y = self.pixel_to_xy(rows, cols)
        if self.geographic:
            return x, y
        return _to_lonlat(x, y, self.epsg)


def _pyproj():
    try:
        import pyproj
    except ImportError:
        return None
    return pyproj


def _to_lonlat(x: np.ndarray, y: np.ndarray, epsg: int | None) -> tuple[np.ndarray, np.ndarray]:
    """Projected ``(x, y)`` in EPSG ``epsg`` to lon/lat through pyproj."""
    if epsg is None:
        raise GeorefError(
            "the file's model is projected but names no EPSG code, so lon/lat are unknown; "
            "pixel_to_xy gives the projected coordinates"
        )
    pyproj = _pyproj()
    if pyproj is None:
        raise GeorefError(
            f"the scene is in projected CRS EPSG:{epsg}; lon/lat need the optional pyproj "
            "package (pip install pyproj); pixel_to_xy gives the projected coordinates"
        )
    t = pyproj.Transformer.from_crs(epsg, 4326, always_xy=True)
    lon, lat = t.transform(x, y)
    return np.asarray(lon, np.float64), np.asarray(lat, np.float64)


@dataclass(frozen=True)
class TiePointGrid:
    """Lon/lat of pixels by bilinear interpolation over a rectilinear grid of tie points.

    Attributes:
        rows: ``(m,)`` increasing raster row coordinates of the grid lines.
        cols: ``(n,)`` increasing raster column coordinates.
        lon: ``(m, n)`` longitudes (degrees), unwrapped (may pass 180).
        lat: ``(m, n)`` latitudes (degrees).
        pixel_is_point: grid coordinates refer to pixel centres (``PixelIsPoint``).

    Examples:
        >>> g = TiePointGrid.from_points([0, 0, 10, 10], [0, 20, 0, 20], [1, 3, 1, 3],
        ...                              [5, 5, 4, 4], pixel_is_point=True)
        >>> [v.tolist() for v in g.pixel_to_lonlat([5.0], [10.0])]
        [[2.0], [4.5]]
    """

    rows: np.ndarray
    cols: np.ndarray
    lon: np.ndarray
    lat: np.ndarray
    pixel_is_point: bool = False
    epsg: int | None = 4326
    geographic: bool = True

    has_lonlat = True

    @classmethod
    def from_points(
        cls,
        rows: object,
        cols: object,
        lon: object,
        lat: object,
        *,
        pixel_is_point: bool = False,
    ) -> TiePointGrid:
        """A grid from scattered tie points that cover every (row, col) grid node once.

        Raises:
            GeorefError: fewer than 2 distinct rows or columns, or points that do not form
                a complete rectilinear grid.
        """
        r, c, x, y = (np.asarray(v, np.float64).ravel() for v in (rows, cols, lon, lat))
        ur, uc = np.unique(r), np.unique(c)
        if len(ur) < 2 or len(uc) < 2:
            raise GeorefError(
                f"tie points span {len(ur)} row(s) and {len(uc)} column(s); a grid needs 2+"
            )
        if len(r) != len(ur) * len(uc):
            raise GeorefError(
                f"{len(r)} tie points do not form a {len(ur)} x {len(uc)} rectilinear grid"
            )
        i, j = np.searchsorted(ur, r), np.searchsorted(uc, c)
        seen = np.zeros((len(ur), len(uc)), bool)
        seen[i, j] = True
        if not seen.all():
            raise GeorefError("tie points repeat a grid node and miss another")
        glon, glat = np.empty(seen.shape), np.empty(seen.shape)
        glon[i, j], glat[i, j] = _unwrap(x), y
        return cls(ur, uc, glon, glat, pixel_is_point=pixel_is_point)

    def pixel_to_lonlat(self, rows: object, cols: object) -> tuple[np.ndarray, np.ndarray]:
        """``(lon, lat)`` in degrees of pixel indices; lon wrapped to [-180, 180)."""
        r, c = _pixels(rows, cols)
        shift = 0.0 if self.pixel_is_point else 0.5
        r, c = r + shift, c + shift
        i = np.clip(np.searchsorted(self.rows, r, side="right") - 1, 0, len(self.rows) - 2)
        j = np.clip(np.searchsorted(self.cols, c, side="right") - 1, 0, len(self.cols) - 2)
        u = (r - self.rows[i]) / (self.rows[i + 1] - self.rows[i])
        v = (c - self.cols[j]) / (self.cols[j + 1] - self.cols[j])

        def interp(g: np.ndarray) -> np.ndarray:
            top = g[i, j] * (1 - v) + g[i, j + 1] * v
            bottom = g[i + 1, j] * (1 - v) + g[i + 1, j + 1] * v
            return top * (1 - u) + bottom * u

        lon = (interp(self.lon) + 180.0) % 360.0 - 180.0
        return lon, interp(self.lat)

    pixel_to_xy = pixel_to_lonlat


def _unwrap(lon: np.ndarray) -> np.ndarray:
    """Longitudes shifted by 360 where a scene crosses the antimeridian."""
    lon = (np.asarray(lon, np.float64) + 180.0) % 360.0 - 180.0
    if lon.size and lon.max() - lon.min() > 180.0:
        lon = np.where(lon < 0, lon + 360.0, lon)
    return lon


def georef_from_tags(tags: Mapping[int, object]) -> AffineGeoref | TiePointGrid | None:
    """The mapping a GeoTIFF's tags describe, or ``None`` when they describe none.

    Args:
        tags: tag code -> value (tuples of numbers), e.g. from ``tifffile.TiffPage.tags``.

    Raises:
        GeorefError: many tie points that do not form a grid, or a singular affine model.
    """
    keys = geokeys(tags.get(GEO_KEY_DIRECTORY))
    model = keys.get(MODEL_TYPE)
    geographic = model == GEOGRAPHIC
    epsg = keys.get(GEOGRAPHIC_TYPE) if geographic else keys.get(PROJECTED_TYPE)
    epsg = epsg if epsg not in (None, 0, 32767) else None  # 32767: user-defined
    point = keys.get(RASTER_TYPE) == PIXEL_IS_POINT
    transform = tags.get(MODEL_TRANSFORMATION)
    ties = tags.get(MODEL_TIEPOINT)
    scale = tags.get(MODEL_PIXEL_SCALE)
    if transform is not None and len(transform) == 16:
        m = [float(v) for v in transform]
        coeffs = (m[0], m[1], m[3], m[4], m[5], m[7])
    elif ties is not None and len(ties) == 6 and scale is not None and len(scale) >= 2:
        i, j, _, x, y, _ = (float(v) for v in ties)
        sx, sy = float(scale[0]), float(scale[1])
        coeffs = (sx, 0.0, x - i * sx, 0.0, -sy, y + j * sy)
    elif ties is not None and len(ties) >= 24 and len(ties) % 6 == 0:
        t = np.asarray(ties, np.float64).reshape(-1, 6)
        if model not in (None, GEOGRAPHIC):
            raise GeorefError("tie-point grids in a projected CRS are not supported")
        return TiePointGrid.from_points(t[:, 1], t[:, 0], t[:, 3], t[:, 4], pixel_is_point=point)
    else:
        return None
    a, b, _, d, e, _ = coeffs
    if a * e - b * d == 0:
        raise GeorefError(f"the affine model {coeffs} is singular (zero pixel size)")
    return AffineGeoref(coeffs, epsg=epsg, geographic=geographic, pixel_is_point=point)


def ground_spacing(
    georef: AffineGeoref | TiePointGrid, shape: tuple[int, int]
) -> tuple[float, float] | None:
    """Approximate ground pixel spacing ``(row_m, col_m)`` at the scene centre from lon/lat.

    Great-circle distance on a sphere of mean Earth radius over 1 % of the scene (at least
    one pixel) either way from the centre; good to a few tenths of a percent. ``None`` when
    the mapping has no lon/lat.

    Examples:
        >>> g = AffineGeoref((1e-4, 0.0, 0.0, 0.0, -1e-4, 0.0), epsg=4326, geographic=True)
        >>> [round(v, 2) for v in ground_spacing(g, (1000, 1000))]
        [11.12, 11.12]
    """
    if not georef.has_lonlat:
        return None
    h, w = shape
    rc, cc = (h - 1) / 2, (w - 1) / 2
    dr, dc = max(1.0, h / 100), max(1.0, w / 100)
    lon, lat = georef.pixel_to_lonlat([rc - dr, rc + dr, rc, rc], [cc, cc, cc - dc, cc + dc])
    lon, lat = np.radians(lon), np.radians(lat)

    def dist(p: int, q: int) -> float:
        s = np.sin((lat[q] - lat[p]) / 2) ** 2 + np.cos(lat[p]) * np.cos(lat[q]) * (
            np.sin((lon[q] - lon[p]) / 2) ** 2
        )
        return float(2 * EARTH_RADIUS_M * np.arcsin(np.sqrt(s)))

    return dist(0, 1) / (2 * dr), dist(2, 3) / (2 * dc)
