"""Fused Triton kernels of the window CFARs without no-data (float32 images, any device
Triton runs on; the interpreter without a GPU).

- :func:`ring_ratio`: CA-CFAR's ``I / mean_ring`` and its mask in one pass. Each pixel's
  ring is summed directly, cell by cell in a fixed order (rows top to bottom, each left to
  right), in float64: ``N`` non-negative float32 terms, so the sum is within ``N 2^-53``
  relative of the exact one, and the float32 statistic within one float32 ulp of the CPU
  kernel's (both round a float64 value that close to the exact ratio). No integral image,
  no cancellation, no intermediate plane.
- :func:`os_decision` / :func:`os_ratio`: OS-CFAR without sorting. The CPU's decision is
  ``g(x_(r)) = f32((I / x_(r)) * scale) > threshold``, and ``g`` is non-increasing in the
  ring value ``x``, so the ring values ``x`` with ``g(x)`` true are a prefix of the sorted
  ring: the pixel is detected iff at least ``r`` ring values lie at or below the largest
  float32 ``c`` with ``g(c)`` true. ``c`` is found by bisection on the order-preserving
  bit patterns of non-negative float32 values (31 evaluations of ``g``), then the ring is
  counted once: the same mask as the CPU's, exactly, by construction. Where the statistic is
  needed, the exact ``x_(r)`` is the smallest float32 ``v`` with ``count(x <= v) >= r``,
  found by the same bisection over the counts (31 counting passes over the ring held in
  registers), and the statistic is then formed as on the CPU, bit for bit.

The border rule of :mod:`torchsar.cfar.core` is applied as the CPU kernels apply it: the
pixel's in-image ring count ``n`` (from its distances to the edges) selects ``scale[n]``
(``1`` at the interior count) and, for OS, the rank ``ranks[n]``.
"""

from __future__ import annotations

import os
import sys

import numpy as np
import torch
from torch import Tensor

# Without a GPU the kernels can only run in Triton's interpreter (on CPU tensors: how the
# tests compare them with the CPU code on such machines), which must be chosen before
# Triton is first imported.
if not torch.cuda.is_available() and "triton" not in sys.modules:
    os.environ.setdefault("TRITON_INTERPRET", "1")

import triton
import triton.language as tl

__all__ = ["os_decision", "os_ratio", "ring_ratio"]


_CA_TILE = (16, 64)  # rows x columns of pixels per program
_OS_CELLS = 8192  # pixels x padded ring cells held per program


@triton.jit
def _in_image(i, n, R):
    """How many of the indices ``i - R .. i + R`` lie in ``0 .. n - 1``."""
    return tl.minimum(i + R, n - 1) - tl.maximum(i - R, 0) + 1


@triton.jit
def _ring_count(i, j, h, w, G, R):
    """In-image cells of the ring (outer box ``R`` minus guard box ``G``) around ``(i, j)``."""
    outer = _in_image(i, h, R) * _in_image(j, w, R)
    return outer - _in_image(i, h, G) * _in_image(j, w, G)


@triton.jit
def _add_cells(acc, ptr, ii, rows, j, w, b0, b1, radius):
    """``acc`` plus the in-image cells of row ``ii`` at column offsets ``b0 - radius .. b1 -
    1 - radius``, left to right, in float64."""
    for b in range(b0, b1):
        jj = j + (b - radius)
        v = tl.load(ptr + ii * w + jj, mask=rows & (jj >= 0) & (jj < w), other=0.0)
        acc += v.to(tl.float64)
    return acc


@triton.jit
def _ring_ratio_kernel(
    x_ptr,
    scale_ptr,
    thr_ptr,
    out_ptr,
    mask_ptr,
    h,
    w,
    G,
    R,
    BH: tl.constexpr,
    BW: tl.constexpr,
):
    pid = tl.program_id(0)
    nbh = tl.cdiv(h, BH)
    nbw = tl.cdiv(w, BW)
    plane = pid // (nbh * nbw)
    tile = pid % (nbh * nbw)
    i = (tile // nbw) * BH + tl.arange(0, BH)[:, None]
    j = (tile % nbw) * BW + tl.arange(0, BW)[None, :]
    base = plane.to(tl.int64) * h * w
    acc = tl.zeros([BH, BW], dtype=tl.float64)
    for a in range(0, 2 * R + 1):  # loops, not unrolled: one compiled kernel for every ring
        ii = i + (a - R)
        rows = (ii >= 0) & (ii < h)
        if (a < R - G) | (a > R + G):  # above or below the guard box: the window's whole row
            acc = _add_cells(acc, x_ptr + base, ii, rows, j, w, 0, 2 * R + 1, R)
        else:  # beside it: left, then right
            acc = _add_cells(acc, x_ptr + base, ii, rows, j, w, 0, R - G, R)
            acc = _add_cells(acc, x_ptr + base, ii, rows, j, w, R + G + 1, 2 * R + 1, R)
    inside = (i < h) & (j < w)
    c = tl.where(inside, _ring_count(i, j, h, w, G, R), 0)
    cf = c.to(tl.float64) * tl.load(scale_ptr + c, mask=inside, other=1.0)
    xi = tl.load(x_ptr + base + i * w + j, mask=inside, other=0.0).to(tl.float64)
    v = xi * cf / acc
    stat = tl.where(v != v, 0.0, v).to(tl.float32)  # 0 / 0 = 0
    tl.store(out_ptr + base + i * w + j, stat, mask=inside)
    tl.store(mask_ptr + base + i * w + j, (stat > tl.load(thr_ptr)).to(tl.int8), mask=inside)


@triton.jit
def _os_statistic(i_val, x, scale):
    """The CPU's OS statistic ``f32((I / x) * scale)`` in float64, ``0 / 0 = 0``."""
    q = i_val / x.to(tl.float64)
    q = tl.where(q != q, 0.0, q)
    return (q * scale).to(tl.float32)


@triton.jit
def _os_kernel(
    x_ptr,
    dr_ptr,
    dc_ptr,
    ranks_ptr,
    scale_ptr,
    thr_ptr,
    out_ptr,
    mask_ptr,
    h,
    w,
    total,
    N,
    NP: tl.constexpr,
    BLOCK: tl.constexpr,
    STAT: tl.constexpr,
):
    q = tl.program_id(0).to(tl.int64) * BLOCK + tl.arange(0, BLOCK)
    live = q < total
    plane = q // (h * w)
    rem = q % (h * w)
    i = (rem // w).to(tl.int32)
    j = (rem % w).to(tl.int32)
    k = tl.arange(0, NP)
    dr = tl.load(dr_ptr + k)
    dc = tl.load(dc_ptr + k)
    ii = i[:, None] + dr[None, :]
    jj = j[:, None] + dc[None, :]
    cell = live[:, None] & (k < N)[None, :] & (ii >= 0) & (ii < h) & (jj >= 0) & (jj < w)
    ring = tl.load(x_ptr + (plane * h * w)[:, None] + ii * w + jj, mask=cell, other=0.0)
    ring = ring + 0.0  # -0.0 as +0.0: the bit patterns below order non-negative values
    n = tl.sum(cell.to(tl.int32), axis=1)
    rank = tl.load(ranks_ptr + n, mask=live, other=1)
    scale = tl.load(scale_ptr + n, mask=live, other=1.0)
    thr = tl.load(thr_ptr)
    i_val = tl.load(x_ptr + q, mask=live, other=0.0).to(tl.float64)
    if STAT:
        # smallest float32 v with count(ring <= v) >= rank: count(hi) >= rank > count(lo)
        lo = tl.full([BLOCK], -1, tl.int32)
        hi = tl.full([BLOCK], 0x7F7FFFFF, tl.int32)  # the largest finite float32
        for _ in range(31):
            mid = lo + (hi - lo) // 2
            below = cell & (ring <= mid.to(tl.float32, bitcast=True)[:, None])
            enough = tl.sum(below.to(tl.int32), axis=1) >= rank
            hi = tl.where(enough, mid, hi)
            lo = tl.where(enough, lo, mid)
        stat = _os_statistic(i_val, hi.to(tl.float32, bitcast=True), scale)
        tl.store(out_ptr + q, stat, mask=live)
        tl.store(mask_ptr + q, (stat > thr).to(tl.int8), mask=live)
    else:
        # largest float32 c with g(c) true: g(lo) true, g(hi) false (+inf: checked apart)
        at_zero = _os_statistic(i_val, tl.zeros([BLOCK], tl.float32), scale) > thr
        at_inf = _os_statistic(i_val, tl.full([BLOCK], float("inf"), tl.float32), scale) > thr
        lo = tl.zeros([BLOCK], tl.int32)
        hi = tl.full([BLOCK], 0x7F800000, tl.int32)
        for _ in range(31):
            mid = lo + (hi - lo) // 2
            g = _os_statistic(i_val, mid.to(tl.float32, bitcast=True), scale) > thr
            lo = tl.where(g, mid, lo)
            hi = tl.where(g, hi, mid)
        cut = tl.where(at_inf, float("inf"), lo.to(tl.float32, bitcast=True))
        count = tl.sum((cell & (ring <= cut[:, None])).to(tl.int32), axis=1)
        tl.store(mask_ptr + q, (at_zero & (count >= rank)).to(tl.int8), mask=live)


def _planes(x: Tensor) -> Tensor:
    return x.detach().reshape(-1, *x.shape[-2:]).contiguous()


def _table(values: np.ndarray, dtype: torch.dtype, device: torch.device) -> Tensor:
    return torch.as_tensor(values, dtype=dtype).to(device)


def ring_ratio(
    x: Tensor, guard: int, train: int, scale: np.ndarray, threshold: Tensor
) -> tuple[Tensor, Tensor]:
    """CA-CFAR's statistic and mask of the float32 image ``x`` ``(..., H, W)``: ``scale``
    (float64, length ``N + 1``) holds the border factor of each ring count (``1`` at ``N``),
    ``threshold`` is a float32 scalar tensor."""
    planes = _planes(x)
    p, h, w = planes.shape
    out = torch.empty_like(planes)
    mask = torch.empty(planes.shape, dtype=torch.bool, device=planes.device)
    if planes.numel():
        bh, bw = _CA_TILE
        grid = (p * triton.cdiv(h, bh) * triton.cdiv(w, bw),)
        _ring_ratio_kernel[grid](
            planes,
            _table(scale, torch.float64, x.device),
            threshold.reshape(1).to(torch.float32),
            out,
            mask.view(torch.int8),
            h,
            w,
            G=guard,
            R=guard + train,
            BH=bh,
            BW=bw,
            enable_fp_fusion=False,  # no fused multiply-adds: IEEE operations as written
        )
    return out.view(x.shape), mask.view(x.shape)


def _os_launch(
    x: Tensor,
    offsets: Tensor,
    ranks: np.ndarray,
    scale: np.ndarray,
    threshold: Tensor,
    statistic: bool,
) -> tuple[Tensor | None, Tensor]:
    planes = _planes(x)
    h, w = planes.shape[-2:]
    n = offsets.shape[0]
    npad = triton.next_power_of_2(n)
    dr = torch.zeros(npad, dtype=torch.int32)
    dc = torch.zeros(npad, dtype=torch.int32)
    dr[:n], dc[:n] = offsets[:, 0].to(torch.int32), offsets[:, 1].to(torch.int32)
    out = torch.empty_like(planes) if statistic else None
    mask = torch.empty(planes.shape, dtype=torch.bool, device=planes.device)
    if planes.numel():
        block = max(1, _OS_CELLS // npad)
        _os_kernel[(triton.cdiv(planes.numel(), block),)](
            planes,
            dr.to(x.device),
            dc.to(x.device),
            _table(ranks, torch.int32, x.device),
            _table(scale, torch.float64, x.device),
            threshold.reshape(1).to(torch.float32),
            out if statistic else mask,  # not written without the statistic
            mask.view(torch.int8),
            h,
            w,
            planes.numel(),
            N=n,
            NP=npad,
            BLOCK=block,
            STAT=statistic,
            enable_fp_fusion=False,
        )
    return (None if out is None else out.view(x.shape)), mask.view(x.shape)


def os_ratio(
    x: Tensor,
    offsets: Tensor,
    ranks: np.ndarray,
    scale: np.ndarray,
    threshold: Tensor,
) -> tuple[Tensor, Tensor]:
    """OS-CFAR's statistic ``I / x_(r)`` (exact order statistic, border rule) and mask of
    the float32 image ``x``: ``offsets`` ``(N, 2)`` are the ring's cells, ``ranks`` and
    ``scale`` (length ``N + 1``) the rank and border factor of each ring count."""
    out, mask = _os_launch(x, offsets, ranks, scale, threshold, statistic=True)
    assert out is not None
    return out, mask


def os_decision(
    x: Tensor,
    offsets: Tensor,
    ranks: np.ndarray,
    scale: np.ndarray,
    threshold: Tensor,
) -> Tensor:
    """OS-CFAR's mask alone, by counting (the arguments of :func:`os_ratio`)."""
    return _os_launch(x, offsets, ranks, scale, threshold, statistic=False)[1]
