"""A whole-scene test file: a big, tiled, compressed GeoTIFF with planted point targets.

:func:`write_scene_file` writes a Sentinel-1-GRD-like measurement file (uint16 amplitude,
BigTIFF, 512 x 512 deflate tiles, a 10 x 21 grid of geographic tie points) full of low
Rayleigh clutter, with a few hundred small bright targets at known positions, and a CSV
of those positions beside it. It is built to exercise windowed readers and tiled
detectors at full scene size (30,000 x 25,000 by default) in bounded memory: tiles are
produced and compressed one at a time, and the clutter tiles are drawn from a seeded pool
compressed once, so writing costs little more than the disk writes.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from torchsar.errors import OptionError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["SceneFile", "scene_lonlat", "write_scene_file"]

DESCRIPTION = "Sentinel-1 GRD-like synthetic scene: uint16 amplitude (torchsar.simulate)"
GRID = (10, 21)  # tie-point lines x pixels, as in Sentinel-1 GRD measurement files
SPACING_M = 10.0
ORIGIN = (4.0, 52.0)  # lon, lat of pixel (0, 0)
HEADING = np.radians(10.0)  # image columns point 10 degrees north of east
METRES_PER_DEGREE = 111_320.0


@dataclass(frozen=True)
class SceneFile:
    """What :func:`write_scene_file` wrote.

    Attributes:
        path: the TIFF.
        targets_csv: the CSV of planted targets (columns below).
        targets: one row per target: ``row``, ``col`` (its brightest pixel), ``height``,
            ``width`` (its extent, 1-3 pixels, centred on the peak, odd sizes exactly
            centred, even sizes extending down/right), ``amplitude`` (peak, DN).
        clutter_sigma: Rayleigh parameter of the clutter amplitude (DN).
    """

    path: Path
    targets_csv: Path
    targets: pd.DataFrame
    clutter_sigma: float


def scene_lonlat(rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The smooth ground mapping the tie points sample: ~10 m pixels, rotated, with a
    slight quadratic stretch along columns (so bilinear interpolation is not exact).

    Examples:
        >>> [round(float(v), 6) for v in scene_lonlat(np.array(0.0), np.array(0.0))]
        [4.0, 52.0]
    """
    r, c = np.asarray(rows, np.float64), np.asarray(cols, np.float64)
    along = c * SPACING_M * (1 + 2e-6 * c)
    east = along * np.cos(HEADING) + r * SPACING_M * np.sin(HEADING)
    north = along * np.sin(HEADING) - r * SPACING_M * np.cos(HEADING)
    lat = ORIGIN[1] + north / METRES_PER_DEGREE
    lon = ORIGIN[0] + east / (METRES_PER_DEGREE * np.cos(np.radians(ORIGIN[1])))
    return lon, lat


def _tie_points(shape: tuple[int, int]) -> list[float]:
    """ModelTiepoint values (I=col, J=row, K, X=lon, Y=lat, Z) on a GRID of pixel centres."""
    h, w = shape
    rows = np.round(np.linspace(0, h - 1, GRID[0]))
    cols = np.round(np.linspace(0, w - 1, GRID[1]))
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    lon, lat = scene_lonlat(rr, cc)
    # tie points name raster coordinates; PixelIsArea puts pixel centres at index + 0.5
    t = np.stack([cc + 0.5, rr + 0.5, 0 * rr, lon, lat, 0 * rr], axis=-1)
    return t.ravel().tolist()


def _geokeys() -> list[int]:
    """GeoKeyDirectory: geographic model, PixelIsArea, WGS 84 (EPSG 4326)."""
    keys = [(1024, 0, 1, 2), (1025, 0, 1, 1), (2048, 0, 1, 4326)]
    return [1, 1, 0, len(keys), *[v for k in keys for v in k]]


def _place_targets(
    rng: np.random.Generator, shape: tuple[int, int], n: int, separation: int
) -> pd.DataFrame:
    """``n`` targets at least ``separation`` pixels apart (Chebyshev), away from edges."""
    h, w = shape
    margin = 4
    if n and (h <= 2 * margin or w <= 2 * margin):
        raise OptionError(f"shape {shape} is too small to plant targets in")
    rows: list[int] = []
    cols: list[int] = []
    tries = 0
    while len(rows) < n:
        tries += 1
        if tries > 100 * n + 1000:
            raise OptionError(
                f"cannot place {n} targets {separation} pixels apart in a {h}x{w} scene"
            )
        r, c = int(rng.integers(margin, h - margin)), int(rng.integers(margin, w - margin))
        if rows:
            d = np.maximum(np.abs(np.array(rows) - r), np.abs(np.array(cols) - c))
            if d.min() < separation:
                continue
        rows.append(r)
        cols.append(c)
    size = rng.integers(1, 4, size=(n, 2))
    amp = rng.integers(2000, 6001, size=n)
    import pandas as pd  # here, not at import: torchsar loads without pandas

    t = pd.DataFrame(
        {"row": rows, "col": cols, "height": size[:, 0], "width": size[:, 1], "amplitude": amp}
    )
    return t.sort_values(["row", "col"], ignore_index=True)


def _stamp(tile: np.ndarray, top: int, left: int, targets: pd.DataFrame) -> None:
    """Paint the targets' pixels into a tile whose corner is ``(top, left)``: the peak at
    (row, col), the other pixels of the extent at half the peak."""
    th, tw = tile.shape
    for r, c, hh, ww, a in targets[["row", "col", "height", "width", "amplitude"]].itertuples(
        index=False
    ):
        r0, c0 = r - (hh - 1) // 2 - top, c - (ww - 1) // 2 - left
        rs, re, cs, ce = max(r0, 0), min(r0 + hh, th), max(c0, 0), min(c0 + ww, tw)
        if rs < re and cs < ce:
            tile[rs:re, cs:ce] = a // 2
        if 0 <= r - top < th and 0 <= c - left < tw:
            tile[r - top, c - left] = a


def write_scene_file(
    path: str | Path,
    *,
    shape: tuple[int, int] = (30_000, 25_000),
    tile: int = 512,
    n_targets: int = 300,
    seed: int = 0,
    clutter_sigma: float = 6.0,
    separation: int = 64,
    pool: int = 32,
    level: int = 1,
) -> SceneFile:
    """Write a big uint16 amplitude GeoTIFF scene with planted targets, and their CSV.

    The file is a tiled BigTIFF (``tile`` x ``tile``, deflate at ``level``), with an
    ImageDescription naming it Sentinel-1-GRD-like (so readers take its samples as
    amplitude) and a 10 x 21 grid of geographic tie points sampling :func:`scene_lonlat`.
    Clutter is Rayleigh amplitude of parameter ``clutter_sigma``; each tile is one of
    ``pool`` seeded clutter tiles (compressed once) unless a target touches it. Targets are
    1-3 pixels on a side, peak amplitude 2000-6000 DN, at least ``separation`` pixels apart.
    Memory stays bounded by the pool (``pool`` tiles) whatever the scene size.

    Args:
        path: the TIFF to write; the CSV goes beside it as ``<stem>.targets.csv``.
        shape: ``(H, W)`` of the scene.
        tile: tile side (a multiple of 16).
        n_targets: how many targets to plant.
        seed: seeds clutter, tile choice and targets (same seed, same file).
        clutter_sigma: Rayleigh parameter of the clutter (DN).
        separation: least distance between targets (pixels, Chebyshev).
        pool: number of distinct clutter tiles.
        level: deflate level (1, the default, is ~10x faster than 6 on clutter and within
            ~5 % of its size).

    Returns:
        a :class:`SceneFile` with the paths and the targets table.

    Raises:
        OptionError: a bad shape, tile, level, pool or target count.

    Examples:
        >>> import tempfile
        >>> out = write_scene_file(tempfile.mkdtemp() + "/s.tif", shape=(600, 500),
        ...                        tile=256, n_targets=5, seed=1, pool=2)
        >>> len(out.targets), out.targets_csv.name
        (5, 's.targets.csv')
    """
    import tifffile

    h, w = _check(shape, tile, n_targets, clutter_sigma, pool, level)
    rng = np.random.default_rng(seed)
    path = Path(path)
    targets = _place_targets(rng, (h, w), n_targets, separation)
    clutter = _clutter_pool(rng, pool, tile, clutter_sigma)
    packed = [_deflate(t, level) for t in clutter]
    tiles = _tiles((h, w), tile, rng, targets, clutter, packed, level)
    extratags = [
        (33922, "d", len(ties := _tie_points((h, w))), ties, False),
        (34735, "H", len(keys := _geokeys()), keys, False),
    ]
    tifffile.imwrite(
        path,
        tiles,
        shape=(h, w),
        dtype=np.uint16,
        tile=(tile, tile),
        compression="zlib",
        bigtiff=True,
        photometric="minisblack",
        description=DESCRIPTION,
        metadata=None,
        extratags=extratags,
    )
    csv = path.with_name(path.stem + ".targets.csv")
    targets.to_csv(csv, index=False)
    return SceneFile(path, csv, targets, float(clutter_sigma))


def _check(shape, tile, n_targets, sigma, pool, level) -> tuple[int, int]:
    ok = isinstance(shape, tuple | list) and len(shape) == 2
    if not ok or not all(isinstance(v, int) and v > 0 for v in shape):
        raise OptionError(f"shape must be two positive integers (H, W), got {shape!r}")
    if not isinstance(tile, int) or tile <= 0 or tile % 16:
        raise OptionError(f"tile must be a positive multiple of 16, got {tile!r}")
    if not isinstance(n_targets, int) or n_targets < 0:
        raise OptionError(f"n_targets must be an integer >= 0, got {n_targets!r}")
    if not (isinstance(sigma, int | float) and 0 < sigma < 300):
        raise OptionError(f"clutter_sigma must be in (0, 300) DN, got {sigma!r}")
    if not isinstance(pool, int) or pool < 1:
        raise OptionError(f"pool must be a positive integer, got {pool!r}")
    if level not in range(10):
        raise OptionError(f"level must be a deflate level 0-9, got {level!r}")
    return int(shape[0]), int(shape[1])


def _clutter_pool(rng: np.random.Generator, n: int, tile: int, sigma: float) -> list[np.ndarray]:
    """``n`` tiles of Rayleigh amplitude clutter, rounded to uint16."""
    out = []
    for _ in range(n):
        u = rng.random((tile, tile))
        out.append(np.round(sigma * np.sqrt(-2.0 * np.log1p(-u))).astype(np.uint16))
    return out


def _deflate(a: np.ndarray, level: int) -> bytes:
    import zlib

    return zlib.compress(np.ascontiguousarray(a, "<u2").tobytes(), level)


def _tiles(
    shape: tuple[int, int],
    tile: int,
    rng: np.random.Generator,
    targets: pd.DataFrame,
    clutter: list[np.ndarray],
    packed: list[bytes],
    level: int,
) -> Iterator[bytes]:
    """Compressed tiles in row-major order: pool tiles, fresh ones where targets or the
    image edge fall (outside the image, tiles are zero)."""
    h, w = shape
    nty, ntx = -(-h // tile), -(-w // tile)
    choice = rng.integers(0, len(clutter), size=(nty, ntx))
    reach = 2  # a target's extent reaches at most 2 pixels from its peak
    by_tile: dict[tuple[int, int], list[int]] = {}
    for i, (r, c) in enumerate(zip(targets["row"], targets["col"], strict=True)):
        for ty in {(r - reach) // tile, (r + reach) // tile}:
            for tx in {(c - reach) // tile, (c + reach) // tile}:
                by_tile.setdefault((ty, tx), []).append(i)
    for ty in range(nty):
        for tx in range(ntx):
            k = int(choice[ty, tx])
            edge = (ty + 1) * tile > h or (tx + 1) * tile > w
            hit = by_tile.get((ty, tx))
            if not hit and not edge:
                yield packed[k]
                continue
            t = clutter[k].copy()
            if hit:
                _stamp(t, ty * tile, tx * tile, targets.iloc[hit])
            t[max(h - ty * tile, 0) :, :] = 0
            t[:, max(w - tx * tile, 0) :] = 0
            yield _deflate(t, level)
