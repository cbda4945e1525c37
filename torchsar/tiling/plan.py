"""Tile planning: cores that partition the scene, and the windows read around them.

Each tile has a *core* (the pixels it is responsible for; cores partition the scene in
raster order) and a *window*: the core widened by the halo on every side, cut at the true
scene border. An operator run on the window gives, on the core, exactly what it gives on
the whole scene when the halo covers its footprint: interior halos hold the real
neighbouring pixels, and a window side cut by the scene border *is* the scene border, so
the operator's own border rule (truncated windows, cut rings) applies there unchanged. No
padding is ever invented.

A window is also widened (within the scene) to at least ``min_side`` pixels, the smallest
image the operator accepts; extra context beyond the footprint changes nothing on the core.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from itertools import groupby

from torchsar._checks import check_int
from torchsar.errors import OptionError, WindowSizeError

__all__ = ["Tile", "batches", "check_tile", "plan_tiles", "widen"]


@dataclass(frozen=True)
class Tile:
    """One tile: ``index`` (tile row, tile column), ``core`` and ``window`` as
    ``(row slice, column slice)`` in scene coordinates."""

    index: tuple[int, int]
    core: tuple[slice, slice]
    window: tuple[slice, slice]

    @property
    def inner(self) -> tuple[slice, slice]:
        """The core in window coordinates."""
        (cr, cc), (wr, wc) = self.core, self.window
        return (
            slice(cr.start - wr.start, cr.stop - wr.start),
            slice(cc.start - wc.start, cc.stop - wc.start),
        )

    @property
    def window_shape(self) -> tuple[int, int]:
        """``(rows, cols)`` of the window."""
        return (
            self.window[0].stop - self.window[0].start,
            self.window[1].stop - self.window[1].start,
        )


def check_tile(tile: object, name: str = "tile") -> tuple[int, int]:
    """``tile`` (an int or a pair of ints, each >= 1) as ``(rows, cols)``."""
    if isinstance(tile, tuple | list) and len(tile) == 2:
        return (check_int(tile[0], name, minimum=1), check_int(tile[1], name, minimum=1))
    if isinstance(tile, tuple | list):
        raise OptionError(f"{name} must be an int or a pair of ints, got {tile!r}")
    t = check_int(tile, name, minimum=1)
    return (t, t)


def _span(start: int, stop: int, halo: int, n: int, min_side: int) -> slice:
    lo, hi = max(0, start - halo), min(n, stop + halo)
    if hi - lo < min_side:  # widen inside the scene (the scene itself is >= min_side)
        hi = min(n, lo + min_side)
        lo = max(0, hi - min_side)
    return slice(lo, hi)


def plan_tiles(
    shape: tuple[int, int], tile: int | tuple[int, int], halo: int, min_side: int = 1
) -> list[Tile]:
    """The tiles of a scene, raster order.

    Args:
        shape: scene ``(H, W)``.
        tile: core side (int) or ``(rows, cols)``; the last row / column of tiles takes the
            remainder (tile sizes need not divide the scene).
        halo: pixels read on each side of a core (>= 0), cut at the scene border.
        min_side: smallest window side (the operator's smallest accepted image).

    Raises:
        OptionError: ``tile`` or ``halo`` not an int, ``tile < 1`` or ``halo < 0``.
        WindowSizeError: the scene is smaller than ``min_side`` (and not empty).

    Examples:
        >>> [(t.core[1], t.window[1]) for t in plan_tiles((4, 10), (4, 4), 2)]
        [(slice(0, 4, None), slice(0, 6, None)), (slice(4, 8, None), slice(2, 10, None)), \
(slice(8, 10, None), slice(6, 10, None))]
    """
    th, tw = check_tile(tile)
    halo = check_int(halo, "halo", minimum=0)
    h, w = shape
    if h == 0 or w == 0:
        return []
    if min(h, w) < min_side:
        raise WindowSizeError(
            f"scene of {h}x{w} pixels is smaller than the operator's {min_side}x{min_side} "
            f"footprint; use a smaller window or a larger scene"
        )
    tiles = []
    for i, r in enumerate(range(0, h, th)):
        rows = slice(r, min(r + th, h))
        wr = _span(rows.start, rows.stop, halo, h, min_side)
        for j, c in enumerate(range(0, w, tw)):
            cols = slice(c, min(c + tw, w))
            tiles.append(
                Tile((i, j), (rows, cols), (wr, _span(cols.start, cols.stop, halo, w, min_side)))
            )
    return tiles


def widen(tile: Tile, halo: int, shape: tuple[int, int], min_side: int = 1) -> Tile:
    """``tile`` with its window re-cut for another ``halo`` (same core)."""
    (cr, cc) = tile.core
    rows = _span(cr.start, cr.stop, halo, shape[0], min_side)
    return Tile(tile.index, tile.core, (rows, _span(cc.start, cc.stop, halo, shape[1], min_side)))


def batches(tiles: list[Tile], batch: int) -> Iterator[list[Tile]]:
    """Tiles grouped by window shape (stackable), in chunks of ``batch``; deterministic:
    by window shape, then raster order."""
    order = sorted(tiles, key=lambda t: (t.window_shape, t.index))
    for _, group in groupby(order, key=lambda t: t.window_shape):
        g = list(group)
        for i in range(0, len(g), batch):
            yield g[i : i + batch]
