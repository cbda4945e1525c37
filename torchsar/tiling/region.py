"""The region-growing CFAR on whole scenes: tiles settled by enlarge-and-redo.

The region CFAR (:func:`torchsar.region.region_cfar`) has no bounded footprint: a region
grows as far as its similarity test allows, seeds are visited brightest first over the
whole image, and every region blocks the pixels it covered from later (dimmer) ones. Its
*local* inputs do have a reach: the despeckled image F (the filter's radius ``r_f``), the
seeds (local maxima of F, ``seed_window // 2`` further), the low-pass image of the
censoring (F, or a box of the raw image), and a region's test reads a ring of
``guard + background`` pixels around it. So a tile's window gives wrong inputs only in a
band of ``d0 = max(r_f + seed_window // 2, lowpass // 2)`` pixels along each *cut* side (a
window side inside the scene; sides on the true scene border are the border).

Settling rule (enlarge-and-redo). Windows run with ``min_size=1`` (the object-size rule
is applied afterwards to the objects merged across seams, which is exactly the untiled
rule: it only looks at the final 8-connected objects). A tile is run at its first halo and
at twice that; its core is accepted at a halo when

1. every tested region that can influence the core is clear of the cut bands: each
   8-connected component of painted pixels (regions the test was applied to, accepted or
   not, and filled holes) meeting the core, and every accepted region within
   ``guard + background + 1`` pixels of one of those (it censored their rings; the
   closure is followed), keeps its bounding box, widened by ``guard + background + d0 + 1``,
   inside the window or on the true scene border; and
2. the core's detections (accepted objects of at least ``min_size`` pixels in the window,
   with their statistic) are the same as at the previous halo.

Otherwise the halo doubles and the tile is redone, up to ``max_halo``; a tile still
unsettled there raises :class:`UnsettledError` (never a silent approximation). A window
covering the whole scene is always settled.

What is guaranteed, and the one non-local effect. Rule 1 makes every tested region near
the core see the same image, seeds, blocking neighbours and censored ring as on the whole
scene. Floods (regions rejected untested as too large) are invisible in the output and
may be arbitrarily large: on speckle the dimmest seeds grow one flood through most of the
clutter (a 1024 x 1024 scene of exponential clutter: one flood of 99 % of the pixels). A
flood covers dimmer seeds before they are visited, so whether a dim clutter peak becomes
a one-pixel tested region depends on where the flood started, possibly outside every
window. Such peaks are isolated and removed by the object-size rule; rule 2 checks that the
detections of the core do not depend on the halo. So the mask and the statistic of
detected pixels reproduce the untiled result (checked on the test scenes and a
4096 x 4096 scene); the statistic of rejected clutter regions (below ``k``) may differ
where floods decide which dim peaks are tested.

``max_fraction`` refers to the *scene* area: it is turned into the equivalent ``max_size``
(a size above ``max_fraction * H * W`` pixels) before tiles are run. Presets without any
size limit (``"paper"``) test every flood, which then never settles on a large scene:
pass ``max_size``.

Memory rule: a window of ``(tile + 2 halo)^2`` pixels costs about 150 bytes per pixel
(float64 copies of the image, F and the low-pass image, the growth state, the painted
statistic), and the first two halos of ``batch`` tiles are held together: about
``150 * batch * ((tile + 2 halo)^2 + (tile + 4 halo)^2)`` bytes over the interpreter, torch
and numba (about 0.4 GB). Defaults (``tile=1024``, ``halo=64``, ``max_halo=512``,
``batch=1``): measured peak 0.82 GB on a 4096 x 4096 scene and 0.85 GB on 16384 x 16384;
the largest halo alone would be 0.6 GB of window.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Collection, Iterator
from dataclasses import replace

import numpy as np
import torch
from scipy import ndimage

from torchsar._checks import check_device, check_int
from torchsar.errors import OptionError, UnsettledError
from torchsar.region.params import RegionParams, resolve_params
from torchsar.region.search import region_search
from torchsar.speckle import FILTERS
from torchsar.tiling.plan import Tile, batches, check_tile, plan_tiles, widen
from torchsar.tiling.source import Scene, as_scene

__all__ = ["UnsettledError", "iter_region_tiles", "region_reach"]

DEFAULT_TILE = 1024
DEFAULT_HALO = 64
DEFAULT_MAX_HALO = 512

_EIGHT = np.ones((3, 3), dtype=bool)


def region_reach(p: RegionParams, despeckle_reach: int | None = None) -> tuple[int, int]:
    """``(d0, ring)``: the band of wrong inputs along a cut side and the test ring width.

    Raises:
        OptionError: ``despeckle`` is a callable and ``despeckle_reach`` is not given.
    """
    if despeckle_reach is not None:
        r_f = check_int(despeckle_reach, "despeckle_reach", minimum=0)
    elif p.despeckle is None:
        r_f = 0
    elif isinstance(p.despeckle, str):
        r_f = int(inspect.signature(FILTERS[p.despeckle]).parameters["window"].default) // 2
    else:
        raise OptionError(
            "despeckle is a callable: pass despeckle_reach (the Chebyshev radius of its "
            "window) so that tiles read enough context"
        )
    r_low = p.lowpass // 2 if isinstance(p.lowpass, int) else 0
    return max(r_f + p.seed_window // 2, r_low), p.guard + p.background


def _scene_params(p: RegionParams, shape: tuple[int, int]) -> RegionParams:
    """``max_fraction`` of the scene area as the equivalent ``max_size`` (sizes are
    integers: ``size > f * A`` iff ``size > floor(f * A)``), the fraction then dropped so
    that windows do not apply it to their own area."""
    if p.max_fraction is None:
        return p
    cap = max(1, math.floor(p.max_fraction * (shape[0] * shape[1])))
    size = cap if p.max_size is None else min(p.max_size, cap)
    return replace(p, max_size=size, max_fraction=None)


def _options(p: RegionParams) -> dict[str, object]:
    return {f: getattr(p, f) for f in RegionParams.__dataclass_fields__}


def _boxes(mask: np.ndarray) -> np.ndarray:
    """``(n, 4)`` inclusive-exclusive boxes ``(r0, r1, c0, c1)`` of the 8-connected
    components of ``mask``."""
    lab, n = ndimage.label(mask, structure=_EIGHT)
    if n == 0:
        return np.zeros((0, 4), np.int64)
    return np.array([(a.start, a.stop, b.start, b.stop) for a, b in ndimage.find_objects(lab)])


def _overlaps(boxes: np.ndarray, box: tuple[int, int, int, int], pad: int) -> np.ndarray:
    r0, r1, c0, c1 = box
    return (
        (boxes[:, 0] < r1 + pad)
        & (boxes[:, 1] > r0 - pad)
        & (boxes[:, 2] < c1 + pad)
        & (boxes[:, 3] > c0 - pad)
    )


def _settled(
    stat: np.ndarray, k: float, tile: Tile, shape: tuple[int, int], ring: int, d0: int
) -> bool:
    """The settling rule of the module docstring, on a window's painted statistic (run
    with ``min_size=1``: every region ever accepted is visible)."""
    (wr, wc), (ir, ic) = tile.window, tile.inner
    h, w = stat.shape
    cut = (wr.start > 0, wr.stop < shape[0], wc.start > 0, wc.stop < shape[1])
    if not any(cut):
        return True
    painted = _boxes(stat > -np.inf)
    core = (ir.start, ir.stop, ic.start, ic.stop)
    todo = list(map(tuple, painted[_overlaps(painted, core, 0)]))
    accepted = _boxes(stat > stat.dtype.type(k))
    seen = np.zeros(len(accepted), dtype=bool)
    margin = ring + d0 + 1
    while todo:
        r0, r1, c0, c1 = box = todo.pop()
        if (
            (cut[0] and r0 < margin)
            or (cut[1] and r1 > h - margin)
            or (cut[2] and c0 < margin)
            or (cut[3] and c1 > w - margin)
        ):
            return False
        near = _overlaps(accepted, box, ring + 1) & ~seen  # censor its ring (step g)
        seen |= near
        todo.extend(map(tuple, accepted[near]))
    return True


def _run_windows(
    scene: Scene, tiles: list[Tile], opts: dict, device: torch.device | None
) -> list[np.ndarray]:
    """The painted statistic of each (same-shape) window, one region_search call."""
    x = torch.stack([torch.from_numpy(scene.read(*t.window)) for t in tiles])[:, None]
    if device is not None:
        x = x.to(device)
    stat = region_search(x, preset="paper", **opts).detection.statistic
    return [s[0].cpu().numpy() for s in stat]


def iter_region_tiles(
    scene: object,
    *,
    tile: int | tuple[int, int] = DEFAULT_TILE,
    halo: int | None = None,
    max_halo: int = DEFAULT_MAX_HALO,
    batch: int = 1,
    device: str | torch.device | None = None,
    despeckle_reach: int | None = None,
    preset: str = "torchsar",
    only: Collection[tuple[int, int]] | None = None,
    **options: object,
) -> Iterator[tuple[Tile, dict[str, np.ndarray]]]:
    """Run the region CFAR over ``scene`` tile by tile, each tile settled by the rule of
    :mod:`torchsar.tiling.region`; yield each tile and its core ``mask`` and ``statistic``
    (numpy). The cores equal :func:`~torchsar.region.region_cfar` on the whole scene.

    Args:
        scene: 2-D intensity scene (tensor, array, memmap or windowed reader).
        tile: core side or ``(rows, cols)`` (default 1024), >= ``2 (d0 + guard + background) + 1``.
        halo: first halo (default ``max(64, d0 + guard + background)``); doubled while a
            tile is unsettled.
        max_halo: the largest halo tried (>= ``halo``).
        batch: windows per region_search call at the first halo (same result).
        device: where the despeckling runs (the growth runs on the CPU).
        despeckle_reach: radius of a callable ``despeckle`` (names are known).
        only: run just the tiles of these indices ``(tile row, tile column)`` (None: all).
        preset, **options: as :func:`~torchsar.region.region_cfar`.

    Raises:
        OptionError: bad ``tile``, ``halo``, ``max_halo``, ``batch`` or region option.
        UnsettledError: a tile not settled at ``max_halo``.
    """
    sc = as_scene(scene)
    p = _scene_params(resolve_params(preset, **options), sc.shape)  # type: ignore[arg-type]
    d0, ring = region_reach(p, despeckle_reach)
    reach = d0 + ring
    size = check_tile(tile)
    if min(size) < 2 * reach + 1:
        raise OptionError(
            f"tile={size} is smaller than the region CFAR's {2 * reach + 1}-pixel footprint "
            f"(despeckle, seeds, guard and background rings); use tile >= {2 * reach + 1}"
        )
    first = max(DEFAULT_HALO, reach) if halo is None else check_int(halo, "halo", minimum=0)
    if first < reach:
        raise OptionError(f"halo={first} is smaller than the region CFAR's reach ({reach} px)")
    max_halo = check_int(max_halo, "max_halo", minimum=first)
    batch = check_int(batch, "batch", minimum=1)
    dev = check_device(device)
    opts = _options(replace(p, min_size=1))  # min_size: on scene objects, after merging
    min_side = 2 * reach + 1
    settle = _Settle(sc, opts, dev, p.k, ring, d0, max_halo, min_side, p.min_size)
    tiles = plan_tiles(sc.shape, size, first, min_side)
    if only is not None:
        keep = {tuple(int(v) for v in i) for i in only}
        tiles = [t for t in tiles if t.index in keep]
    for group in batches(tiles, batch):
        second = [widen(t, min(2 * first, max_halo), sc.shape, min_side) for t in group]
        firsts = _run_windows(sc, group, opts, dev)
        once = first >= max_halo or group[0].window_shape == sc.shape  # nothing to compare
        seconds = [] if once else _run_windows(sc, second, opts, dev)
        for i, t in enumerate(group):
            if once:
                t_done, core = settle(t, firsts[i], None, first)
            else:
                before = settle.detected(firsts[i], t)
                t_done, core = settle(second[i], seconds[i], before, 2 * first)
            yield t_done, {"mask": core > core.dtype.type(p.k), "statistic": core}


class _Settle:
    """The enlarge-and-redo loop of one tile (see the module docstring)."""

    def __init__(self, sc, opts, dev, k, ring, d0, max_halo, min_side, min_size) -> None:
        self.sc, self.opts, self.dev, self.k = sc, opts, dev, k
        self.ring, self.d0, self.max_halo, self.min_side = ring, d0, max_halo, min_side
        self.min_size = min_size

    def detected(self, stat: np.ndarray, t: Tile) -> np.ndarray:
        """The core's detections after the object-size rule applied in the window: the
        statistic on pixels of accepted objects of ``min_size`` pixels or more, ``-inf``
        elsewhere (what the settled output is compared on)."""
        mask = stat > stat.dtype.type(self.k)
        lab, n = ndimage.label(mask, structure=_EIGHT)
        big = np.bincount(lab.reshape(-1), minlength=n + 1) >= self.min_size
        big[0] = False
        core = stat[t.inner]
        return np.where(big[lab[t.inner]], core, -np.inf)

    def __call__(
        self, t: Tile, stat: np.ndarray, prev: np.ndarray | None, halo: int
    ) -> tuple[Tile, np.ndarray]:
        """Settle tile ``t`` whose window (for ``halo``) gave ``stat``; ``prev`` is the core
        at the previous halo (None: none yet). Returns the tile and its settled core."""
        shape = self.sc.shape
        while True:
            found = self.detected(stat, t)
            if t.window_shape == shape or (
                _settled(stat, self.k, t, shape, self.ring, self.d0)
                and prev is not None
                and np.array_equal(prev, found)
            ):
                return t, stat[t.inner]
            if halo >= self.max_halo:
                raise UnsettledError(
                    f"region CFAR tile {t.index} (scene rows {t.core[0].start}:"
                    f"{t.core[0].stop}, cols {t.core[1].start}:{t.core[1].stop}) is not settled "
                    f"at max_halo={self.max_halo}: its regions reach a cut side of the window or "
                    f"its core still changes with the halo; pass a larger max_halo"
                )
            prev, halo = found, min(2 * halo, self.max_halo)
            t = widen(t, halo, shape, self.min_side)
            stat = _run_windows(self.sc, [t], self.opts, self.dev)[0]
