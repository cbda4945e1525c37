"""Ordered-statistic CFAR (the module is not named ``os``: importing ``torchsar.cfar.os``
would replace the function ``torchsar.cfar.os`` by the module)."""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache, partial

import numpy as np
import torch
from torch import Tensor

from torchsar import _jit, _triton
from torchsar._checks import check_image, check_int, check_probability
from torchsar.cfar.core import (
    border_scale,
    conclude,
    finish,
    geometric_scale,
    out_dtype,
    prepare,
    ratio,
    rescale_border_,
    valid_planes,
)
from torchsar.cfar.thresholds import factor_map, os_factor, os_rank
from torchsar.detection import WINDOW, Detection, DetectorSpec
from torchsar.errors import OptionError
from torchsar.order_statistics import ring_order_statistic
from torchsar.windows import Ring, Sums, disjoint_rects, region_count, windowed

__all__ = ["os", "os_mask", "os_threshold"]


def os(
    x: Tensor,
    *,
    guard: int = 2,
    train: int = 4,
    pfa: float = 1e-3,
    rank: int | None = None,
    valid: Tensor | None = None,
) -> Detection:
    """Ordered-statistic CFAR: statistic ``I / x_(r)``, the exact r-th smallest ring value.

    The threshold factor solves Rohling's ``pfa = prod_{i=0}^{r-1} (N-i)/(N-i+alpha)`` by
    bisection (exponential clutter; :func:`~torchsar.cfar.thresholds.os_factor`). The order
    statistic is exact at every pixel (:func:`~torchsar.order_statistics.ring_order_statistic`).

    Border rule: a pixel with ``n < N`` counted ring cells uses rank
    ``round(r n / N)`` (at least 1) and its statistic is rescaled by
    ``alpha(N, r) / alpha(n, r_n)``, so one global threshold keeps the design ``pfa``.

    Args:
        x: intensity ``(B, C, H, W)``, non-negative and finite.
        guard: guard half-width g.
        train: training-band width t; ``N = (2(g+t)+1)^2 - (2g+1)^2``.
        pfa: design probability of false alarm.
        rank: r in ``[1, N]`` (default ``round(3N/4)``, Rohling's recommendation).
        valid: optional bool mask of usable cells.

    Returns:
        :class:`Detection` with ``threshold = alpha(N, r)``.

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        Rohling, H., IEEE TAES 19(4), 608-621, 1983, doi:10.1109/TAES.1983.309350.

    Examples:
        >>> x = torch.ones(1, 1, 16, 16); x[0, 0, 8, 8] = 100.0
        >>> os(x, guard=1, train=2).mask.sum().item()
        1
    """
    ring, pfa, vmask = prepare(x, guard, train, pfa, valid, detector="os", values=False)
    r = _check_rank(rank, ring)
    check_image(x, "x")  # the values last, after every option
    factor = partial(_factor, n_full=ring.n, rank=r, pfa=pfa)
    if vmask is None and _triton.for_tensor(x):
        *tables, thr = _gpu_args(x, ring, r, factor)
        stat, mask = _triton.kernels().os_ratio(x, *tables, thr)
        return Detection(mask=mask, statistic=stat, threshold=thr)
    if _jit.for_tensor(x) and x.numel():
        return conclude(_compiled(x, ring, r, factor, vmask), vmask, factor(ring.n))
    counts = _ring_counts(x, ring, vmask)
    ranks = factor_map(counts, partial(os_rank, n_full=ring.n, rank=r)).long()
    est = ring_order_statistic(x, ring, ranks, valid=vmask)
    # ``+ 0.0``: an order statistic of -0.0 is zero (``I / 0 = +inf``, as on every path)
    stat = ratio(x.to(torch.float64), est.to(torch.float64).add_(0.0))
    rescale_border_(stat, counts, ring.n, factor)
    stat = finish(stat, counts, out_dtype(x))
    return conclude(stat, vmask, factor(ring.n))


def os_mask(
    x: Tensor,
    *,
    guard: int = 2,
    train: int = 4,
    pfa: float = 1e-3,
    rank: int | None = None,
    valid: Tensor | None = None,
) -> Tensor:
    """The mask of :func:`os` alone (the same pixels exactly), for a scan that needs no
    statistic.

    For float32 images without a ``valid`` mask no order statistic is formed: a pixel is
    detected iff at least ``r`` of its ring values lie at or below the largest value ``c``
    whose statistic would pass the threshold (the passing values are a prefix of the sorted
    ring), and the ring is only counted (on a GPU by the Triton kernels, on the CPU by a
    compiled kernel: about three times faster than :func:`os`). Elsewhere it is
    ``os(...).mask``.

    Args:
        x, guard, train, pfa, rank, valid: as for :func:`os`.

    Returns:
        bool ``(B, C, H, W)``.

    Examples:
        >>> x = torch.ones(1, 1, 16, 16); x[0, 0, 8, 8] = 100.0
        >>> os_mask(x, guard=1, train=2).sum().item()
        1
    """
    ring, checked, vmask = prepare(x, guard, train, pfa, valid, detector="os_mask", values=False)
    r = _check_rank(rank, ring)
    check_image(x, "x")  # the values last, after every option
    factor = partial(_factor, n_full=ring.n, rank=r, pfa=checked)
    if vmask is None and _triton.for_tensor(x):
        return _triton.kernels().os_decision(x, *_gpu_args(x, ring, r, factor))
    if vmask is None and x.dtype == torch.float32 and _jit.for_tensor(x) and x.numel():
        return _compiled_decision(x, ring, r, factor)
    return os(x, guard=guard, train=train, pfa=pfa, rank=rank, valid=valid).mask


def _compiled_decision(x: Tensor, ring: Ring, rank: int, factor: Callable[[int], float]) -> Tensor:
    """:func:`os_mask` on the CPU by :func:`torchsar.cfar._kernels.os_decision` (counting,
    no order statistic; float32 without no-data)."""
    from torchsar.cfar import _kernels

    h, w = x.shape[-2:]
    counts, ranks = _geometry(h, w, ring, rank)
    scale = geometric_scale(h, w, ring, factor)
    planes = x.detach().reshape(-1, h, w).contiguous()
    out = torch.empty(planes.shape, dtype=torch.bool)
    thr = np.float32(factor(ring.n))  # the threshold as the float32 statistic meets it
    _kernels.os_decision(
        planes.numpy(), ring.outer, ring.guard, counts, ranks.numpy(), scale, thr, out.numpy()
    )
    return out.view(x.shape)


def _gpu_tables(
    x: Tensor, ring: Ring, rank: int, factor: Callable[[int], float]
) -> tuple[tuple[int, int], Tensor, np.ndarray, np.ndarray]:
    """The Triton kernels' description of the ring: ``(guard, train)``, its cells ``(N,
    2)``, and the rank and border factor of each ring count (length ``N + 1``)."""
    ranks = np.array([os_rank(n, ring.n, rank) for n in range(ring.n + 1)], dtype=np.int32)
    scale = geometric_scale(*x.shape[-2:], ring, factor)
    return (ring.guard, ring.train), ring.offsets(), ranks, scale


def _gpu_args(x: Tensor, ring: Ring, rank: int, factor: Callable[[int], float]) -> tuple:
    """:func:`_gpu_tables` and the threshold ``alpha(N, r)`` as the statistic's dtype on
    ``x``'s device: the Triton kernels' arguments after the image."""
    thr = torch.tensor(factor(ring.n), dtype=x.dtype, device=x.device)
    return (*_gpu_tables(x, ring, rank, factor), thr)


def os_threshold(*, guard: int, train: int, pfa: float, rank: int | None) -> float:
    """The design threshold ``alpha(N, r)`` of :func:`os` for these options (no image
    needed)."""
    ring = Ring(guard, train)
    return _factor(ring.n, ring.n, _check_rank(rank, ring), check_probability(pfa, "pfa"))


def _check_rank(rank: int | None, ring: Ring) -> int:
    if rank is None:
        return max(1, round(3 * ring.n / 4))
    r = check_int(rank, "rank", minimum=1)
    if r > ring.n:
        raise OptionError(f"rank must be in [1, N={ring.n}] (the ring's cell count), got {rank}")
    return r


def _compiled(
    x: Tensor, ring: Ring, rank: int, factor: Callable[[int], float], vmask: Tensor | None
) -> Tensor:
    """The statistic on CPU with the compiled kernels, the same values bit for bit as the
    tensor code: the order statistic by the sliding rank bitset and ``I / x_(k)`` with the
    border factor by :func:`torchsar.cfar._kernels.os_ratio`. Without no-data the ring
    counts, ranks and border factors depend only on the geometry (remembered per image
    size); with it the valid ring cells are counted per plane (exact, from an integral
    image of the mask) and the ranks and factors looked up per count."""
    from torchsar.cfar import _kernels

    h, w = x.shape[-2:]
    if vmask is None:
        counts, ranks = _geometry(h, w, ring, rank)
        counts, scale = counts[None], geometric_scale(h, w, ring, factor)
    else:
        counts = _valid_counts(x, ring, vmask)
        table = np.array([os_rank(c, ring.n, rank) for c in range(ring.n + 1)], np.int64)
        ranks = torch.from_numpy(table[counts]).view(x.shape)
        scale = border_scale(range(ring.n + 1), ring.n, factor)
    est = ring_order_statistic(x, ring, ranks, valid=vmask)
    planes = x.detach().reshape(-1, h, w).contiguous().numpy()
    out = torch.empty(planes.shape, dtype=out_dtype(x))
    _kernels.os_ratio(planes, est.reshape(-1, h, w).numpy(), counts, ring.n, scale, out.numpy())
    return out.view(x.shape)


def _valid_counts(x: Tensor, ring: Ring, vmask: Tensor) -> np.ndarray:
    """The valid ring cells of every pixel, int64 ``(P, H, W)`` (exact)."""
    from torchsar import _windows_kernels

    rects = np.array(disjoint_rects(ring.region), np.int64)
    counts = _windows_kernels.valid_counts(valid_planes(vmask, x), rects)
    return counts.astype(np.int64)


@lru_cache(maxsize=16)
def _geometry(h: int, w: int, ring: Ring, rank: int) -> tuple[np.ndarray, Tensor]:
    """The in-image ring count (int64 ``(H, W)``) and the rank used at each pixel (``(H,
    W)``) of an ``h x w`` image without no-data."""
    counts = region_count(h, w, ring.region)
    ranks = factor_map(counts, partial(os_rank, n_full=ring.n, rank=rank)).long()
    return counts.round().long().numpy(), ranks


def _ring_counts(x: Tensor, ring: Ring, vmask: Tensor | None) -> Tensor:
    """Counted ring cells per pixel, float64: ``(H, W)`` without a mask, else ``(B, C, H, W)``."""
    if vmask is None:
        return region_count(*x.shape[-2:], ring.region, x.device)

    def count(_xs: Tensor, sums: list[Sums]) -> Tensor:
        return sums[0].count.clone()

    return windowed(x, [ring.region], count, valid=vmask, moments=1)


def _factor(n: int, n_full: int, rank: int, pfa: float) -> float:
    return os_factor(n, os_rank(n, n_full, rank), pfa)


SPEC = DetectorSpec(
    name="os", detect=os, order=4, options={**WINDOW, "rank": None}, threshold=os_threshold
)
"""The registry entry of this detector (:class:`~torchsar.detection.DetectorSpec`)."""
