"""Shared machinery of the pinwheel-block CFARs (GO, SO): block means, their max / min, and
the exact threshold factor for each pixel's block sizes."""

from __future__ import annotations

import functools
from functools import partial

import numpy as np
import torch
from torch import Tensor

from torchsar import _jit, _triton
from torchsar._checks import check_image, check_probability
from torchsar.cfar.core import (
    conclude,
    finish,
    geometric_cached,
    kernel_planes,
    one_sweep,
    out_dtype,
    prepare,
    ratio,
    refuse_values,
    valid_planes,
)
from torchsar.cfar.thresholds import block_factor, keyed_factor_map
from torchsar.detection import Detection
from torchsar.windows import Ring, Sums, pinwheel_rects, windowed

__all__ = [
    "block_cfar",
    "block_scale",
    "block_threshold",
    "border_states",
    "extreme_mean",
    "pinwheel_states",
]

_NAMES = {"max": "go", "min": "so"}


def extreme_mean(sums: list[Sums], reduce: str) -> Tensor:
    """``max`` or ``min`` over the non-empty blocks of the block means (float64), at least 0
    (the means of non-negative data: a block of zeros whose shifted sums leave a negative
    residue is 0, not a negative mean that would turn the statistic's sign)."""
    fill = -torch.inf if reduce == "max" else torch.inf
    means = [torch.where(s.count > 0, s.mean(), fill) for s in sums]
    stacked = torch.stack(torch.broadcast_tensors(*means), dim=0)
    out = stacked.amax(0) if reduce == "max" else stacked.amin(0)
    return (out if reduce == "max" else torch.where(out.isinf(), 0.0, out)).clamp_min(0.0)


def block_scale(counts: list[Tensor], interior: tuple[int, ...], factor) -> Tensor | None:
    """``factor(interior) / factor(counts)`` per pixel where the block sizes differ from the
    interior ones (``None`` when every pixel has the interior sizes)."""
    c = torch.stack(torch.broadcast_tensors(*counts), dim=-1)
    full = torch.tensor(interior, dtype=c.dtype, device=c.device)
    other = (c != full).any(-1)
    if not bool(other.any()):
        return None
    scale = torch.ones(other.shape, dtype=torch.float64, device=c.device)
    scale[other] = factor(interior) / keyed_factor_map(c[other], factor)
    return scale


def block_cfar(
    x: Tensor, guard: int, train: int, pfa: float, valid: Tensor | None, reduce: str
) -> Detection:
    """GO (``reduce="max"``) or SO (``"min"``) CFAR on the 4 pinwheel blocks."""
    ring, pfa, vmask = prepare(x, guard, train, pfa, valid, detector=_NAMES[reduce], values=False)
    compiled = not _triton.for_tensor(x) and _jit.for_tensor(x) and x.numel()
    if not compiled:  # the compiled kernels check the values as they read them
        check_image(x, "x")
    rects = pinwheel_rects(ring.guard, ring.train)
    interior = tuple(r.area for r in rects)
    factor = partial(_factor, pfa=pfa, reduce=reduce)
    dtype = out_dtype(x)
    if compiled and vmask is not None:
        stat = _compiled_valid_blocks(x, ring, vmask, reduce, factor, dtype)
        return conclude(stat, vmask, factor(interior))
    if compiled:
        return _compiled_block_cfar(x, ring, pfa, reduce, dtype)

    def statistic(xs: Tensor, sums: list[Sums]) -> Tensor:
        est = extreme_mean(sums, reduce)
        stat = ratio(xs.to(est.dtype), est)
        counts = [s.count for s in sums]
        scale = geometric_cached(
            ("block", interior, pfa, reduce),
            counts,
            lambda: block_scale(counts, interior, factor),
            geometric=vmask is None,
        )
        if scale is not None:
            stat = stat * scale
        return finish(stat, sum(counts), dtype)

    stat = windowed(x, rects, statistic, valid=vmask, moments=1)
    return conclude(stat, vmask, factor(interior))


def _compiled_valid_blocks(
    x: Tensor, ring: Ring, vmask: Tensor, reduce: str, factor, dtype: torch.dtype
) -> Tensor:
    """:func:`block_cfar`'s statistic with no-data on the CPU in one sweep per image plane
    (:func:`torchsar._pinwheel_kernels.block_ratio_valid`: each block's valid cells and
    their count summed directly), then the border factors of the blocks' counts
    (:func:`block_scale`) and the ending (``-inf`` where no block has a valid cell)."""
    from torchsar import _pinwheel_kernels

    planes = kernel_planes(x)
    stat = np.empty(planes.shape)
    counts = np.empty((4, *planes.shape))
    valid = valid_planes(vmask, x)
    g, t = ring.guard, ring.train
    if _pinwheel_kernels.block_ratio_valid(
        planes.numpy(), valid, g, t, reduce == "max", stat, counts
    ):
        refuse_values(x)
    interior = tuple(r.area for r in pinwheel_rects(g, t))
    flat = counts.reshape(4, -1)
    ranks = _pinwheel_kernels.size_ranks(flat, np.array(interior, np.int64))
    edge = np.flatnonzero(ranks >= 0)
    if edge.size:  # the border factors, each distinct size tuple's once
        known = _size_factors(interior, factor.keywords["pfa"], reduce)
        keys, first, which = np.unique(ranks[edge], return_index=True, return_inverse=True)
        found = np.empty(keys.size)
        for i, (key, k) in enumerate(zip(keys.tolist(), edge[first].tolist(), strict=True)):
            if key not in known:  # (idempotent: threads may share the table)
                known[key] = factor(tuple(sorted(int(c) for c in flat[:, k])))
            found[i] = known[key]
        # full times the reciprocal, as torch divides a number by a tensor: bit for bit
        # the statistic the tensor code gives
        with np.errstate(invalid="ignore"):  # -inf times a factor of 0: NaN, as torch
            stat.reshape(-1)[edge] *= (factor(interior) * (1.0 / found))[which]
    count = [torch.from_numpy(c).view(x.shape) for c in counts]
    return finish(torch.from_numpy(stat).view(x.shape), sum(count), dtype)


@functools.lru_cache(maxsize=8)
def _size_factors(interior: tuple[int, ...], pfa: float, reduce: str) -> dict[int, float]:
    """The GO / SO factors of the block sizes met so far with no-data, by the rank of the
    ascending sizes (:func:`torchsar._pinwheel_kernels.size_ranks`). A mask gives
    thousands of size tuples per image, a few hundred ascending ones, most of them the
    same from image to image: each factor (a numerical integration) is evaluated once.
    Entries are only ever added, with values that do not depend on who computes them."""
    return {}


def _compiled_block_cfar(
    x: Tensor, ring: Ring, pfa: float, reduce: str, dtype: torch.dtype
) -> Detection:
    """:func:`block_cfar` without no-data on the CPU in one sweep per image plane
    (:func:`torchsar._pinwheel_kernels.block_ratio`: the blocks summed directly, within a
    float32 ulp of the exact means; the border factors from :func:`border_states`)."""
    from torchsar import _pinwheel_kernels

    g, t = ring.guard, ring.train
    rows, cols, table = border_states(*x.shape[-2:], g, t, pfa, reduce)
    interior = tuple(r.area for r in pinwheel_rects(g, t))

    def kernel(planes, thr, out, mask):
        is_max = reduce == "max"
        return _pinwheel_kernels.block_ratio(
            planes, g, t, is_max, rows, cols, table, thr, out, mask
        )

    return one_sweep(x, kernel_planes(x), dtype, _factor(interior, pfa, reduce), kernel)


def pinwheel_states(
    h: int, w: int, guard: int, train: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The four pinwheel blocks' in-image rows at each row of an ``h x w`` image without
    no-data and their in-image columns at each column, as states: ``(row_states, rows,
    col_states, cols)``, row ``i``'s four row counts ``row_states[rows[i]]`` (``(R, 4)``
    int64), likewise the columns. A block's size at ``(i, j)`` is the product of the two."""
    rects = pinwheel_rects(guard, train)

    def states(n: int, spans: list[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
        i = np.arange(n)[:, None]
        lo, hi = np.array(spans).T
        inside = np.clip(np.minimum(i + hi, n - 1) - np.maximum(i + lo, 0) + 1, 0, None)
        uniq, index = np.unique(inside, axis=0, return_inverse=True)
        return uniq, index.reshape(-1).astype(np.int64)

    row_states, rows = states(h, [(r.r0, r.r1) for r in rects])
    col_states, cols = states(w, [(r.c0, r.c1) for r in rects])
    return row_states, rows, col_states, cols


@functools.lru_cache(maxsize=32)
def border_states(
    h: int, w: int, guard: int, train: int, pfa: float, reduce: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The border factors of GO / SO in an ``h x w`` image without no-data, as a table:
    ``table[rows[i], cols[j]]`` is pixel ``(i, j)``'s ``factor(interior) / factor(its
    block sizes)`` (as :func:`block_scale` gives it; 1 where the sizes are the interior's,
    ``-inf`` where no block has a cell), from :func:`pinwheel_states`."""
    interior = tuple(r.area for r in pinwheel_rects(guard, train))
    row_states, rows, col_states, cols = pinwheel_states(h, w, guard, train)
    table = np.ones((len(row_states), len(col_states)))
    for a, rs in enumerate(row_states):
        for b, cs in enumerate(col_states):
            sizes = tuple(int(v) for v in rs * cs)
            if sum(sizes) == 0:
                table[a, b] = -np.inf
            elif sizes != interior:
                # as block_scale's float / tensor: torch takes the reciprocal, then multiplies
                table[a, b] = _factor(interior, pfa, reduce) * (1.0 / _factor(sizes, pfa, reduce))
    return rows, cols, table


def block_threshold(guard: int, train: int, pfa: float, reduce: str) -> float:
    """The design threshold of GO (``reduce="max"``) / SO (``"min"``) for these options:
    the factor of the interior block sizes (no image needed)."""
    rects = pinwheel_rects(Ring(guard, train).guard, train)
    return _factor(tuple(r.area for r in rects), check_probability(pfa, "pfa"), reduce)


def _factor(sizes: tuple[int, ...], pfa: float, reduce: str) -> float:
    return block_factor(tuple(sorted(sizes)), pfa, reduce)
