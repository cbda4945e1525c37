"""MSTAR-like target chips: one vehicle-like target with its shadow on homogeneous clutter."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import torch

from torchsar._checks import check_int, check_positive, check_range
from torchsar.errors import OptionError
from torchsar.seeding import Draws
from torchsar.simulate.batch import BatchOptions, SimBatch, build_batch, speckle_canvas
from torchsar.simulate.canvas import Canvas
from torchsar.simulate.shapes import RotatedRect
from torchsar.simulate.targets import place, random_heading, rasterise

__all__ = ["ChipOptions", "chips"]

_MARGIN = 2


@dataclass(frozen=True)
class ChipOptions:
    """Validated target options shared by chips and scene vehicles."""

    target_db: tuple[float, float]
    length_px: tuple[float, float]
    width_ratio: tuple[float, float]
    shadow_ratio: tuple[float, float]
    shadow_gain: tuple[float, float]

    @staticmethod
    def check(target_db, length_px, width_ratio, shadow_ratio, shadow_gain) -> ChipOptions:
        """Validate every range option (see :func:`chips`)."""
        return ChipOptions(
            check_range(target_db, "target_db", minimum=0.0),
            check_range(length_px, "length_px", minimum=4.0),
            check_range(width_ratio, "width_ratio", minimum=0.05, maximum=1.0),
            check_range(shadow_ratio, "shadow_ratio", minimum=0.0),
            check_range(shadow_gain, "shadow_gain", minimum=0.0, maximum=1.0),
        )


def _min_size(opts: ChipOptions) -> int:
    """Smallest chip that holds the longest, widest target at any heading."""
    diagonal = opts.length_px[1] * math.hypot(1.0, opts.width_ratio[1])
    return math.ceil(diagonal) + 2 * _MARGIN + 1


def _centre(low: float, high: float, offset: float, draws: Draws) -> float:
    """Centre of ``[low, high]`` moved by up to ``offset`` px, kept inside the interval."""
    return min(high, max(low, 0.5 * (low + high) + draws.uniform(-offset, offset)))


def _chip_target(size: int, opts: ChipOptions, offset: float, draws: Draws) -> dict:
    """Draw the chip target geometry: a rectangle whose body and shadow fit in the chip."""
    length = draws.uniform(*opts.length_px)
    width = length * draws.uniform(*opts.width_ratio)
    heading = random_heading(draws)
    shadow = round(length * draws.uniform(*opts.shadow_ratio))
    gain = draws.uniform(*opts.shadow_gain)
    hr, hc = RotatedRect(0.0, 0.0, length, width, heading).half_extent()
    last = size - 1 - _MARGIN
    shadow = max(0, min(shadow, math.floor(last - _MARGIN - 2 * hr)))
    row = _centre(_MARGIN + hr, last - hr - shadow, offset, draws)
    col = _centre(_MARGIN + hc, last - hc, offset, draws)
    rect = RotatedRect(row, col, length, width, heading)
    return {"rect": rect, "shadow_px": shadow, "shadow_gain": gain}


def _render_chip(
    gen: torch.Generator, *, size: int, opts: ChipOptions, offset: float, common: BatchOptions
) -> dict:
    """Render one chip from its generator (geometry, levels, then clutter)."""
    draws = Draws(gen)
    canvas = Canvas(torch.ones((size, size), device=gen.device))
    geo = _chip_target(size, opts, offset, draws)
    raster = rasterise(geo["rect"], (size, size), gen.device)
    canvas.paint(
        place(
            "vehicle",
            geo["rect"],
            raster,
            db=opts.target_db,
            clutter_mean=1.0,
            shadow_px=geo["shadow_px"],
            shadow_gain=geo["shadow_gain"],
            draws=draws,
        )
    )
    return speckle_canvas(canvas, gen, common, regions={"kind": "homogeneous", "mean_db": 0.0})


def chips(
    n: int,
    *,
    size: int = 128,
    model: str = "gamma",
    looks: float = 1.0,
    shape_param: float | None = None,
    seed: int = 0,
    start: int = 0,
    pixel_m: float = 0.3,
    target_db: tuple[float, float] = (15.0, 35.0),
    length_px: tuple[float, float] = (20.0, 60.0),
    width_ratio: tuple[float, float] = (0.4, 0.55),
    shadow_ratio: tuple[float, float] = (0.3, 0.7),
    shadow_gain: tuple[float, float] = (0.05, 0.1),
    offset_px: float = 6.0,
    device: torch.device | str | None = None,
) -> SimBatch:
    """Simulate MSTAR-like chips: one vehicle-like target with its radar shadow.

    The target is a rectangle ``length x width`` (``length ~ U(length_px)``,
    ``width = length * U(width_ratio)``) at a heading uniform in ``[0, 180)`` degrees, centred
    in the chip up to ``offset_px``; its body holds a few dominant point scatterers on weaker
    facet returns, every body pixel between ``target_db`` dB over the clutter mean (1.0); see
    :mod:`torchsar.simulate.targets`. The shadow (the body swept ``length * U(shadow_ratio)``
    pixels towards far range = increasing rows, clutter times ``U(shadow_gain)``) is marked
    in ``ignore``. The image is ``clean * clutter`` with unit-mean clutter of the chosen model
    (:func:`torchsar.simulate.clutter`). Image ``i`` uses only the generator seeded with
    ``image_seed(seed, start + i)``, so results do not depend on the batch size.

    Args:
        n: number of chips, >= 0.
        size: chip side in pixels; must hold the longest target at any heading.
        model: clutter model name (``"exponential"``, ``"gamma"``, ``"k"``, ``"g0"``,
            ``"lognormal"``, ``"weibull"``), as in :func:`torchsar.simulate.clutter`.
        looks: speckle looks (gamma/k/g0).
        shape_param: clutter shape parameter (model default when ``None``; the allowed
            range of each model is in :mod:`torchsar.simulate.clutter`).
        seed: batch seed in ``[0, 2**63)``.
        start: index of the first image (``chips(1, start=i)[0] == chips(n)[i]``).
        pixel_m: pixel spacing in metres (recorded in ``meta``).
        target_db: body levels in dB over the clutter mean, ``(low, high)``.
        length_px: target length range in pixels.
        width_ratio: width / length range.
        shadow_ratio: shadow length / target length range.
        shadow_gain: shadow intensity / clutter mean range.
        offset_px: maximum displacement of the target centre from the chip centre.
        device: output device (default CPU); it must be available.

    Returns:
        A :class:`SimBatch` of ``n`` images ``(n, 1, size, size)``, one instance each.

    Raises:
        OptionError: invalid count, size, model name, looks, shape_param, ranges, seed or
            device (e.g. ``"cuda"`` on a machine without a GPU).

    References:
        Ross, T. D. et al. (1998). Standard SAR ATR evaluation experiments using the MSTAR
        public release data set. Proc. SPIE 3370. DOI: 10.1117/12.321859

    Examples:
        >>> b = chips(3, size=96, length_px=(20, 40), seed=1)
        >>> b.image.shape, b.instances.max().item()
        (torch.Size([3, 1, 96, 96]), 1)
    """
    common = BatchOptions.check(n, seed, start, model, looks, shape_param, pixel_m, device)
    opts = ChipOptions.check(target_db, length_px, width_ratio, shadow_ratio, shadow_gain)
    size = check_int(size, "size", minimum=1)
    if size < _min_size(opts):
        raise OptionError(
            f"size must be >= {_min_size(opts)} to hold a target of length {opts.length_px[1]:g} "
            f"px at any heading, got {size}; use a larger size or smaller length_px"
        )
    offset = check_positive(offset_px, "offset_px", allow_zero=True)
    render = partial(_render_chip, size=size, opts=opts, offset=offset, common=common)
    return build_batch(common, (size, size), render)
