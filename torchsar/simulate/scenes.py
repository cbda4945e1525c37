"""Large heterogeneous scenes: clutter regions with sharp edges and many targets of mixed kinds.

Targets (every instance separated from the others by at least 2 px, inside the image):

- vehicles: like the chip target (:mod:`torchsar.simulate.targets`), ``vehicle_px`` long;
- buildings (``large=True``): 1–3 bright rectangles ``building_px`` long (30–120 px, larger
  than usual CFAR windows), width 0.5–1 of the length, bright rim and corners;
- groups (``groups=True``): 1–2 rows of 2–5 parallel vehicles only 2–6 px apart;
- near-edge vehicles (``edges=True``): ~40 % of the single vehicles are centred within a few
  pixels of a clutter-region boundary.

Each target's levels are ``target_db`` over the clutter mean at its centre
(``meta["targets"][j]["clutter_mean"]``); every target casts a shadow towards increasing rows,
marked in ``ignore``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import torch
from torch import Tensor

from torchsar._checks import check_int, check_range
from torchsar.errors import OptionError
from torchsar.seeding import Draws
from torchsar.simulate.batch import BatchOptions, SimBatch, build_batch, speckle_canvas
from torchsar.simulate.canvas import Canvas
from torchsar.simulate.regions import background, edge_pixels
from torchsar.simulate.shapes import RotatedRect
from torchsar.simulate.targets import place, random_heading, rasterise

__all__ = ["SceneOptions", "scenes"]

_MARGIN = 2
_GAP = 6  # keep-out distance (px) between separately placed targets
_TRIES = 40


@dataclass(frozen=True)
class SceneOptions:
    """Validated scene options (see :func:`scenes`)."""

    n_targets: tuple[int, int]
    regions: tuple[int, int]
    road: bool
    large: bool
    groups: bool
    edges: bool
    target_db: tuple[float, float]
    vehicle_px: tuple[float, float]
    building_px: tuple[float, float]
    shadow_ratio: tuple[float, float] = (0.3, 0.7)
    shadow_gain: tuple[float, float] = (0.05, 0.1)


@dataclass
class _Scene:
    """Per-image state while placing targets."""

    canvas: Canvas
    labels: Tensor
    edges: Tensor
    opts: SceneOptions
    draws: Draws


def _shadow(length: float, s: _Scene) -> tuple[int, float]:
    """Shadow length (px) and gain for a target of ``length``."""
    return round(length * s.draws.uniform(*s.opts.shadow_ratio)), s.draws.uniform(
        *s.opts.shadow_gain
    )


def _centre(s: _Scene, near_edge: bool, reach: float) -> tuple[float, float]:
    """A random centre: uniform in the image, or within ``reach`` px of a region edge."""
    H, W = s.canvas.shape
    if near_edge and len(s.edges):
        k = s.draws.integer(0, len(s.edges) - 1)
        r, c = s.edges[k].tolist()
        return r + s.draws.uniform(-reach, reach), c + s.draws.uniform(-reach, reach)
    return s.draws.uniform(0, H - 1), s.draws.uniform(0, W - 1)


def _fits(s: _Scene, rects: list[RotatedRect]) -> list | None:
    """Rasters of ``rects`` if all lie inside the image on free pixels, else ``None``."""
    H, W = s.canvas.shape
    if not all(r.inside_image(H, W, _MARGIN) for r in rects):
        return None
    rasters = [rasterise(r, (H, W), s.draws.generator.device) for r in rects]
    return rasters if all(s.canvas.is_free(x.box, x.body) for x in rasters) else None


def _paint(s: _Scene, kind: str, rects: list[RotatedRect], rasters: list, **extra) -> None:
    """Draw levels and shadows of accepted rectangles, paint them and keep out their area."""
    for rect, raster in zip(rects, rasters, strict=True):
        row = min(max(round(rect.row), 0), s.canvas.shape[0] - 1)
        col = min(max(round(rect.col), 0), s.canvas.shape[1] - 1)
        mean = float(s.canvas.background[row, col])
        shadow_px, gain = _shadow(rect.length, s)
        s.canvas.paint(
            place(
                kind,
                rect,
                raster,
                db=s.opts.target_db,
                clutter_mean=mean,
                shadow_px=shadow_px,
                shadow_gain=gain,
                draws=s.draws,
            )
        )
        s.canvas.targets[-1].update(extra)
    for raster in rasters:
        s.canvas.reserve(raster.box, raster.body, _GAP)


def _try_place(s: _Scene, kind: str, make, near_edge: bool = False, **extra) -> int:
    """Up to ``_TRIES`` attempts at placing the rectangles ``make(row, col)``; count placed."""
    for _ in range(_TRIES):
        rects, reach = make()
        row, col = _centre(s, near_edge, reach)
        rects = [RotatedRect(row + r.row, col + r.col, r.length, r.width, r.heading) for r in rects]
        rasters = _fits(s, rects)
        if rasters is not None:
            _paint(s, kind, rects, rasters, near_edge=near_edge, **extra)
            return len(rects)
    return 0


def _vehicle(s: _Scene, ratio: tuple[float, float] = (0.4, 0.55)):
    """One vehicle rectangle centred at the origin, and its edge-placement reach."""
    length = s.draws.uniform(*s.opts.vehicle_px)
    width = length * s.draws.uniform(*ratio)
    return [RotatedRect(0.0, 0.0, length, width, random_heading(s.draws))], 0.5 * width + 3


def _building(s: _Scene):
    """One building rectangle centred at the origin."""
    length = s.draws.uniform(*s.opts.building_px)
    width = length * s.draws.uniform(0.5, 1.0)
    return [RotatedRect(0.0, 0.0, length, width, random_heading(s.draws))], 0.0


def _group(s: _Scene, members: int):
    """``members`` parallel vehicles side by side, 2–6 px apart, centred at the origin."""
    length = s.draws.uniform(*s.opts.vehicle_px)
    heading = random_heading(s.draws)
    widths = [length * s.draws.uniform(0.4, 0.55) for _ in range(members)]
    gaps = [s.draws.uniform(2.0, 6.0) for _ in range(members - 1)]
    offsets = [0.0]
    for i, gap in enumerate(gaps):
        offsets.append(offsets[-1] + 0.5 * widths[i] + gap + 0.5 * widths[i + 1])
    mid = 0.5 * offsets[-1]
    # the v axis is (cos h, -sin h) in (row, col): perpendicular to the long axis
    c, sn = math.cos(heading), math.sin(heading)
    rects = [
        RotatedRect((o - mid) * c, -(o - mid) * sn, length * s.draws.uniform(0.9, 1.1), w, heading)
        for o, w in zip(offsets, widths, strict=True)
    ]
    return rects, 0.0


def _plan(s: _Scene) -> tuple[int, int, list[int]]:
    """Numbers of targets: (total, buildings, group sizes)."""
    lo, hi = s.opts.n_targets
    total = s.draws.integer(lo, hi)
    buildings = min(total, s.draws.integer(1, 3)) if s.opts.large else 0
    sizes = []
    if s.opts.groups:
        for _ in range(s.draws.integer(1, 2)):
            members = s.draws.integer(2, 5)
            if buildings + sum(sizes) + members <= total:
                sizes.append(members)
    return total, buildings, sizes


def _populate(s: _Scene) -> None:
    """Place buildings, then groups, then single vehicles (some near region edges)."""
    total, buildings, sizes = _plan(s)
    for _ in range(buildings):
        _try_place(s, "building", partial(_building, s), group=-1)
    for g, members in enumerate(sizes):
        _try_place(s, "vehicle", partial(_group, s, members), group=g)
    singles = total - buildings - sum(sizes)
    for _ in range(singles):
        near = s.opts.edges and s.draws.uniform(0.0, 1.0) < 0.4
        _try_place(s, "vehicle", partial(_vehicle, s), near_edge=near, group=-1)


def _render_scene(
    gen: torch.Generator, *, size: int, opts: SceneOptions, common: BatchOptions
) -> dict:
    """Render one scene from its generator: regions, targets, then clutter."""
    draws = Draws(gen)
    mean, labels, regions = background((size, size), opts.regions, opts.road, draws)
    s = _Scene(Canvas(mean), labels, edge_pixels(labels), opts, draws)
    _populate(s)
    return speckle_canvas(s.canvas, gen, common, regions=regions, region_map=labels)


def _check_count_range(value: object, name: str, minimum: int) -> tuple[int, int]:
    """Validate a ``(low, high)`` pair of ints with ``minimum <= low <= high``."""
    ok = isinstance(value, tuple | list) and len(value) == 2
    ok = ok and all(isinstance(v, int) and not isinstance(v, bool) for v in value)
    if not ok or not minimum <= value[0] <= value[1]:
        raise OptionError(
            f"{name} must be a pair (low, high) of ints, {minimum} <= low <= high; got {value!r}"
        )
    return int(value[0]), int(value[1])


def _check_flag(value: object, name: str) -> bool:
    """Validate a bool option."""
    if not isinstance(value, bool):
        raise OptionError(f"{name} must be True or False, got {value!r}")
    return value


def scenes(
    n: int,
    *,
    size: int = 512,
    model: str = "gamma",
    looks: float = 1.0,
    shape_param: float | None = None,
    seed: int = 0,
    start: int = 0,
    pixel_m: float = 0.3,
    n_targets: tuple[int, int] = (5, 30),
    regions: tuple[int, int] = (3, 8),
    road: bool = True,
    large: bool = True,
    groups: bool = True,
    edges: bool = True,
    target_db: tuple[float, float] = (15.0, 35.0),
    vehicle_px: tuple[float, float] = (10.0, 40.0),
    building_px: tuple[float, float] = (30.0, 120.0),
    device: torch.device | str | None = None,
) -> SimBatch:
    """Simulate heterogeneous scenes with many targets of mixed kinds and their ground truth.

    The background is ``regions`` Voronoi patches of field (``U(-3, 0)`` dB) or forest
    (``U(1, 4)`` dB) with a straight road strip (``U(-6, -4)`` dB, 6–14 px wide) when
    ``road``: sharp edges, means up to 10 dB apart (:mod:`torchsar.simulate.regions`). On it,
    ``U(n_targets)`` targets are planned (see the module docstring for kinds); each is placed by
    rejection sampling (at most 40 tries) so instances never overlap, stay 2 px inside the
    image and are at least 6 px from other targets (2–6 px inside a group). When the scene is
    crowded fewer targets than planned may be placed; ``meta["boxes"]`` lists those placed.
    ``meta["region_map"]`` is the ``(H, W)`` int16 region label map (the road is the last
    label) and ``meta["regions"]`` describes each region. The image is ``clean * clutter``
    with unit-mean clutter of the chosen model; image ``i`` depends only on
    ``image_seed(seed, start + i)``.

    Args:
        n: number of scenes, >= 0.
        size: scene side in pixels; must hold the largest target.
        model, looks, shape_param: clutter model (as in :func:`torchsar.simulate.clutter`).
        seed: batch seed in ``[0, 2**63)``.
        start: index of the first image.
        pixel_m: pixel spacing in metres (recorded in ``meta``).
        n_targets: ``(low, high)`` number of targets planned per scene.
        regions: ``(low, high)`` number of Voronoi regions.
        road: add a road strip.
        large: add 1–3 buildings.
        groups: add 1–2 tight vehicle groups.
        edges: place ~40 % of single vehicles near region edges.
        target_db: target levels in dB over the local clutter mean.
        vehicle_px: vehicle length range in pixels.
        building_px: building length range in pixels.
        device: output device (default CPU); it must be available.

    Returns:
        A :class:`SimBatch` of ``n`` images ``(n, 1, size, size)``.

    Raises:
        OptionError: invalid count, size, model, looks, shape_param, ranges, flags, seed or
            device (e.g. ``"cuda"`` on a machine without a GPU).

    Examples:
        >>> b = scenes(1, size=256, n_targets=(5, 8), building_px=(30, 60))
        >>> b.image.shape, 1 <= int(b.instances.max()) <= 8
        (torch.Size([1, 1, 256, 256]), True)
    """
    common = BatchOptions.check(n, seed, start, model, looks, shape_param, pixel_m, device)
    opts = SceneOptions(
        _check_count_range(n_targets, "n_targets", 0),
        _check_count_range(regions, "regions", 1),
        _check_flag(road, "road"),
        _check_flag(large, "large"),
        _check_flag(groups, "groups"),
        _check_flag(edges, "edges"),
        check_range(target_db, "target_db", minimum=0.0),
        check_range(vehicle_px, "vehicle_px", minimum=4.0),
        check_range(building_px, "building_px", minimum=8.0),
    )
    size = check_int(size, "size", minimum=1)
    longest = max(opts.vehicle_px[1] * 1.15, opts.building_px[1] * math.sqrt(2.0) if large else 0)
    need = math.ceil(longest) + 2 * _MARGIN + 1
    if size < need:
        raise OptionError(
            f"size must be >= {need} to hold the largest target, got {size}; "
            f"use a larger size or smaller vehicle_px / building_px"
        )
    render = partial(_render_scene, size=size, opts=opts, common=common)
    return build_batch(common, (size, size), render)
