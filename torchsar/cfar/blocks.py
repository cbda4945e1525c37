"""Shared machinery of the pinwheel-block CFARs (GO, SO): block means, their max / min, and
the exact threshold factor for each pixel's block sizes."""

from __future__ import annotations

from functools import partial

import torch
from torch import Tensor

from torchsar import _jit
from torchsar._checks import check_probability
from torchsar.cfar.core import (
    conclude,
    finish,
    geometric_cached,
    out_dtype,
    prepare,
    ratio,
    stack_planes,
)
from torchsar.cfar.thresholds import block_factor, keyed_factor_map
from torchsar.detection import Detection
from torchsar.windows import Ring, Sums, pinwheel_rects, windowed

__all__ = ["block_cfar", "block_scale", "block_threshold", "extreme_mean"]

_NAMES = {"max": "go", "min": "so"}


def extreme_mean(sums: list[Sums], reduce: str) -> Tensor:
    """``max`` or ``min`` over the non-empty blocks of the block means (float64)."""
    fill = -torch.inf if reduce == "max" else torch.inf
    means = [torch.where(s.count > 0, s.mean(), fill) for s in sums]
    stacked = torch.stack(torch.broadcast_tensors(*means), dim=0)
    out = stacked.amax(0) if reduce == "max" else stacked.amin(0)
    return out.clamp_min(0.0) if reduce == "max" else torch.where(out.isinf(), 0.0, out)


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
    ring, pfa, vmask = prepare(x, guard, train, pfa, valid, detector=_NAMES[reduce])
    rects = pinwheel_rects(ring.guard, ring.train)
    interior = tuple(r.area for r in rects)
    factor = partial(_factor, pfa=pfa, reduce=reduce)
    dtype = out_dtype(x)

    def statistic(xs: Tensor, sums: list[Sums]) -> Tensor:
        if _jit.for_tensor(xs):
            stat = _compiled_extreme_ratio(xs, sums, reduce)
        else:
            est = extreme_mean(sums, reduce)
            stat = ratio(xs.to(est.dtype), est)
        counts = [s.count for s in sums]
        scale = geometric_cached(
            ("block", interior, pfa, reduce), counts, lambda: block_scale(counts, interior, factor)
        )
        if scale is not None:
            stat = stat * scale
        return finish(stat, sum(counts), dtype)

    stat = windowed(x, rects, statistic, valid=vmask, moments=1)
    return conclude(stat, vmask, factor(interior))


def _compiled_extreme_ratio(xs: Tensor, sums: list[Sums], reduce: str) -> Tensor:
    """``xs / extreme_mean(sums, reduce)`` (as :func:`ratio`) by
    :func:`torchsar.cfar._kernels.block_extreme_ratio`, bit for bit."""
    from torchsar.cfar import _kernels

    count = stack_planes([s.count for s in sums])
    s1 = stack_planes([s.s1 for s in sums])
    shift = sums[0].shift.reshape(xs.shape[:2])
    out = _kernels.block_extreme_ratio(
        xs.contiguous().numpy(), count.numpy(), s1.numpy(), shift.numpy(), reduce == "max"
    )
    return torch.from_numpy(out)


def block_threshold(guard: int, train: int, pfa: float, reduce: str) -> float:
    """The design threshold of GO (``reduce="max"``) / SO (``"min"``) for these options:
    the factor of the interior block sizes (no image needed)."""
    rects = pinwheel_rects(Ring(guard, train).guard, train)
    return _factor(tuple(r.area for r in rects), check_probability(pfa, "pfa"), reduce)


def _factor(sizes: tuple[int, ...], pfa: float, reduce: str) -> float:
    return block_factor(tuple(sorted(sizes)), pfa, reduce)
