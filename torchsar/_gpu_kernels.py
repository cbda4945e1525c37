"""Fused Triton kernels of the window CFARs (float32 images, any device Triton runs on;
the interpreter without a GPU): CA and OS without no-data, every window's sums with it
too.

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
  float32 ``c`` with ``g(c)`` true. ``c`` is the rounded ``I scale / threshold`` moved by
  an ulp or two (checked on both sides), or, where that guess does not settle it, found by
  bisection on the order-preserving bit patterns of non-negative float32 values; then the
  ring is counted once, row by row: the same mask as the CPU's, exactly, by construction.
  Where the statistic is needed, the exact ``x_(r)`` is the smallest float32 ``v`` with
  ``count(x <= v) >= r``, found by bisection over the counts (31 counting passes over the
  ring held in registers, cells x pixels), and the statistic is then formed as on the CPU,
  bit for bit.
- :func:`region_sums`: every other window statistic's sums (GO, SO, two-parameter, VI, the
  distribution CFARs, the speckle filters' window moments): ``sum(x - shift)`` and its
  squares over disjoint rectangles, cell by cell in float64, instead of integral images,
  ``shift`` a cell of the pixel's own window (not the image's mean, which a bright target
  far away moves: the variance of a ring of zeros beside it did not cancel to 0).

Tiles whose windows lie inside the image load without masks. Launches run on the input's
own GPU, with fused multiply-adds off (every operation rounded as written).

The border rule of :mod:`torchsar.cfar.core` is applied as the CPU kernels apply it: the
pixel's in-image ring count ``n`` (from its distances to the edges) selects ``scale[n]``
(``1`` at the interior count) and, for OS, the rank ``ranks[n]``.
"""

from __future__ import annotations

import os
import sys
from contextlib import contextmanager
from functools import lru_cache

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

__all__ = ["os_decision", "os_ratio", "region_sums", "ring_ratio"]


_CA_TILE = (16, 64)  # rows x columns of pixels per program


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
def _row_cells(
    acc, ptr, ii, rows, j, w, b0, b1, radius, cut, COUNT: tl.constexpr, MASKED: tl.constexpr
):
    """``acc`` plus the cells of row ``ii`` at column offsets ``b0 - radius .. b1 - 1 -
    radius``, left to right: their values in float64, or (``COUNT``) how many lie at or
    below ``cut``; the in-image ones (``MASKED``), or all of them (a tile whose windows lie
    inside the image: no masks to form)."""
    for b in range(b0, b1):
        jj = j + (b - radius)
        if MASKED:
            m = rows & (jj >= 0) & (jj < w)
            v = tl.load(ptr + ii * w + jj, mask=m, other=0.0)
            if COUNT:
                acc += (m & (v <= cut)).to(tl.int32)
            else:
                acc += v.to(tl.float64)
        else:
            v = tl.load(ptr + ii * w + jj)
            if COUNT:
                acc += (v <= cut).to(tl.int32)
            else:
                acc += v.to(tl.float64)
    return acc


@triton.jit
def _ring_cells(acc, ptr, i, j, h, w, G, R, cut, COUNT: tl.constexpr, MASKED: tl.constexpr):
    """:func:`_row_cells` over the ring around every pixel of the tile (``acc``: its zero
    tile), rows top to bottom, each row left to right."""
    for a in range(0, 2 * R + 1):  # loops, not unrolled: one compiled kernel for every ring
        ii = i + (a - R)
        rows = (ii >= 0) & (ii < h)
        if (a < R - G) | (a > R + G):  # above or below the guard box: the window's whole row
            acc = _row_cells(acc, ptr, ii, rows, j, w, 0, 2 * R + 1, R, cut, COUNT, MASKED)
        else:  # beside it: left, then right
            acc = _row_cells(acc, ptr, ii, rows, j, w, 0, R - G, R, cut, COUNT, MASKED)
            acc = _row_cells(acc, ptr, ii, rows, j, w, R + G + 1, 2 * R + 1, R, cut, COUNT, MASKED)
    return acc


@triton.jit
def _tile(rows, w, BH: tl.constexpr, BW: tl.constexpr):
    """The plane, first row and first column of this program's tile of ``BH x BW`` pixels
    (the programs run over planes of ``rows x w`` pixels tile by tile, row-major)."""
    pid = tl.program_id(0)
    nbh = tl.cdiv(rows, BH)
    nbw = tl.cdiv(w, BW)
    tile = pid % (nbh * nbw)
    return pid // (nbh * nbw), (tile // nbw) * BH, (tile % nbw) * BW


@triton.jit
def _interior(row0, col0, h, w, R, BH: tl.constexpr, BW: tl.constexpr):
    """Whether every window of radius ``R`` around the tile at ``(row0, col0)`` lies in the
    image."""
    return (row0 >= R) & (row0 + BH - 1 + R < h) & (col0 >= R) & (col0 + BW - 1 + R < w)


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
    plane, row0, col0 = _tile(h, w, BH, BW)
    i = row0 + tl.arange(0, BH)[:, None]
    j = col0 + tl.arange(0, BW)[None, :]
    base = plane.to(tl.int64) * h * w
    zero = tl.zeros([BH, BW], dtype=tl.float64)
    if _interior(row0, col0, h, w, R, BH, BW):
        acc = _ring_cells(zero, x_ptr + base, i, j, h, w, G, R, 0.0, False, False)
    else:
        acc = _ring_cells(zero, x_ptr + base, i, j, h, w, G, R, 0.0, False, True)
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
def _os_cutoff(i_val, scale, thr, inside, BH: tl.constexpr, BW: tl.constexpr):
    """The largest float32 ``c >= 0`` whose statistic passes (``+inf`` when every value's
    does), and whether ``g(0)`` passes (if not, no value does). The rounded ``I s / thr``
    is within an ulp or two of ``c``: where it and its neighbours bracket the boundary
    (``g`` true two below, false two above) ``c`` is the largest of them that passes
    (seven evaluations of ``g``); the other pixels (zero or infinite guesses, thresholds at
    or below zero) take a bisection on the bit patterns of non-negative float32 values,
    run only in the tiles that have such a pixel."""
    at_zero = _os_statistic(i_val, tl.zeros([BH, BW], tl.float32), scale) > thr
    at_inf = _os_statistic(i_val, tl.full([BH, BW], float("inf"), tl.float32), scale) > thr
    guess = (i_val * scale / thr.to(tl.float64)).to(tl.float32)
    start = guess.to(tl.int32, bitcast=True)
    # (the threshold as a tile: Triton's interpreter turns ``scalar bool & tile`` into ints)
    ok = ((thr + tl.zeros_like(guess)) > 0) & (guess > 0) & (guess < float("inf")) & (start >= 2)
    start = tl.where(ok, start, 2)
    near = ok & _os_passes(i_val, start - 2, scale, thr)
    near = near & (_os_passes(i_val, start + 2, scale, thr) == 0)
    lo = start - 2
    for k in range(-1, 2):  # the largest passing of start - 1 .. start + 1 (g is monotone)
        lo = tl.where(near & _os_passes(i_val, start + k, scale, thr), start + k, lo)
    # only pixels in the image whose answer is neither "none" (g(0) false) nor "all"
    # (g(inf) true) and that the guess did not settle
    unsettled = inside & at_zero & (at_inf == 0) & (near == 0)
    if tl.sum(unsettled.to(tl.int32)) > 0:
        slow_lo = tl.zeros([BH, BW], tl.int32)
        slow_hi = tl.full([BH, BW], 0x7F800000, tl.int32)
        for _ in range(31):
            mid = slow_lo + (slow_hi - slow_lo) // 2
            g = _os_passes(i_val, mid, scale, thr)
            slow_lo = tl.where(g, mid, slow_lo)
            slow_hi = tl.where(g, slow_hi, mid)
        lo = tl.where(near, lo, slow_lo)
    return tl.where(at_inf, float("inf"), lo.to(tl.float32, bitcast=True)), at_zero


@triton.jit
def _os_passes(i_val, bits, scale, thr):
    """Whether the ring value with the float32 bit pattern ``bits`` would pass."""
    return _os_statistic(i_val, bits.to(tl.float32, bitcast=True), scale) > thr


@triton.jit
def _os_decision_kernel(
    x_ptr,
    ranks_ptr,
    scale_ptr,
    thr_ptr,
    mask_ptr,
    h,
    w,
    G,
    R,
    BH: tl.constexpr,
    BW: tl.constexpr,
):
    plane, row0, col0 = _tile(h, w, BH, BW)
    i = row0 + tl.arange(0, BH)[:, None]
    j = col0 + tl.arange(0, BW)[None, :]
    inside = (i < h) & (j < w)
    ptr = x_ptr + plane.to(tl.int64) * h * w
    n = tl.where(inside, _ring_count(i, j, h, w, G, R), 0)
    rank = tl.load(ranks_ptr + n, mask=inside, other=1)
    scale = tl.load(scale_ptr + n, mask=inside, other=1.0)
    i_val = tl.load(ptr + i * w + j, mask=inside, other=0.0).to(tl.float64)
    cut, at_zero = _os_cutoff(i_val, scale, tl.load(thr_ptr), inside, BH, BW)
    zero = tl.zeros([BH, BW], dtype=tl.int32)
    if _interior(row0, col0, h, w, R, BH, BW):
        count = _ring_cells(zero, ptr, i, j, h, w, G, R, cut, True, False)
    else:
        count = _ring_cells(zero, ptr, i, j, h, w, G, R, cut, True, True)
    detected = (at_zero & (rank > 0) & (count >= rank)).to(tl.int8)  # rank 0: no ring
    tl.store(mask_ptr + plane.to(tl.int64) * h * w + i * w + j, detected, mask=inside)


@triton.jit
def _os_ratio_kernel(
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
    G,
    R,
    NP: tl.constexpr,
    BH: tl.constexpr,
    BW: tl.constexpr,
):
    # a tile of BH x BW pixels as one vector of BLOCK pixels, row by row
    BLOCK: tl.constexpr = BH * BW
    plane, row0, col0 = _tile(h, w, BH, BW)
    p = tl.arange(0, BLOCK)
    i = row0 + p // BW
    j = col0 + p % BW
    live = (i < h) & (j < w)
    ptr = x_ptr + plane.to(tl.int64) * h * w
    # the ring held ring-major (cells x pixels: loads run along the row), NaN where a cell
    # is outside the image or padding (NaN is at or below nothing: never counted)
    k = tl.arange(0, NP)
    ii = i[None, :] + tl.load(dr_ptr + k)[:, None]
    jj = j[None, :] + tl.load(dc_ptr + k)[:, None]
    cell = (ii >= 0) & (ii < h) & (jj >= 0) & (jj < w) & live[None, :]
    ring = tl.load(ptr + ii * w + jj, mask=cell, other=float("nan"))
    n = tl.where(live, _ring_count(i, j, h, w, G, R), 0)
    rank = tl.load(ranks_ptr + n, mask=live, other=1)
    # the smallest float32 v with count(ring <= v) >= rank: count(hi) >= rank > count(lo)
    lo = tl.full([BLOCK], -1, tl.int32)
    hi = tl.full([BLOCK], 0x7F7FFFFF, tl.int32)  # the largest finite float32
    for _ in range(31):
        mid = lo + (hi - lo) // 2
        below = ring <= mid.to(tl.float32, bitcast=True)[None, :]
        enough = tl.sum(below.to(tl.int32), axis=0) >= rank
        hi = tl.where(enough, mid, hi)
        lo = tl.where(enough, lo, mid)
    scale = tl.load(scale_ptr + n, mask=live, other=1.0)
    i_val = tl.load(ptr + i * w + j, mask=live, other=0.0).to(tl.float64)
    stat = _os_statistic(i_val, hi.to(tl.float32, bitcast=True), scale)
    stat = tl.where(n > 0, stat, float("-inf"))  # no ring cell: untestable, as on the CPU
    at = plane.to(tl.int64) * h * w + i * w + j
    tl.store(out_ptr + at, stat, mask=live)
    tl.store(mask_ptr + at, (stat > tl.load(thr_ptr)).to(tl.int8), mask=live)


@triton.jit
def _rect(rect_ptr, t):
    """Rectangle ``t`` of the table: its row offsets ``a0 .. a1`` and column offsets
    ``b0 .. b1``."""
    a0 = tl.load(rect_ptr + 4 * t)
    a1 = tl.load(rect_ptr + 4 * t + 1)
    b0 = tl.load(rect_ptr + 4 * t + 2)
    b1 = tl.load(rect_ptr + 4 * t + 3)
    return a0, a1, b0, b1


@triton.jit
def _cell(ptr, vptr, ii, jj, w, m, VALID: tl.constexpr):
    """The cells ``(ii, jj)`` where ``m`` (and, ``VALID``, where ``vptr`` flags them
    valid): that mask and their values in float64 (0 elsewhere)."""
    if VALID:
        m = m & (tl.load(vptr + ii * w + jj, mask=m, other=0) != 0)
    return m, tl.load(ptr + ii * w + jj, mask=m, other=0.0).to(tl.float64)


@triton.jit
def _deviation_sums(
    ptr,
    vptr,
    i,
    j,
    h,
    w,
    shift,
    rect_ptr,
    t0,
    t1,
    BH: tl.constexpr,
    BW: tl.constexpr,
    MOMENTS: tl.constexpr,
    MASKED: tl.constexpr,
    VALID: tl.constexpr,
):
    """``sum(x - shift)``, ``sum((x - shift)^2)`` and the count of cells over the
    rectangles ``t0 .. t1 - 1`` of the table around every pixel of the tile (``shift``: a
    tile of per-pixel values), cell by cell in float64: only in-image cells where
    ``MASKED``, only valid ones (``vptr``: 1 for a valid cell) where ``VALID``."""
    s1 = tl.zeros([BH, BW], dtype=tl.float64)
    s2 = tl.zeros([BH, BW], dtype=tl.float64)
    n = tl.zeros([BH, BW], dtype=tl.int32)
    for t in range(t0, t1):
        a0, a1, b0, b1 = _rect(rect_ptr, t)
        for a in range(a0, a1 + 1):
            ii = i + a
            rows = (ii >= 0) & (ii < h)
            for b in range(b0, b1 + 1):
                jj = j + b
                if MASKED:
                    m, v = _cell(ptr, vptr, ii, jj, w, rows & (jj >= 0) & (jj < w), VALID)
                    d = tl.where(m, v - shift, 0.0)
                    if VALID:
                        n += m.to(tl.int32)
                else:
                    d = tl.load(ptr + ii * w + jj).to(tl.float64) - shift
                s1 += d
                if MOMENTS >= 2:
                    s2 += d * d
    return s1, s2, n


@triton.jit
def _first_cell(ptr, i, j, h, w, rect_ptr, n_rects, BH: tl.constexpr, BW: tl.constexpr):
    """The value (float64) of the first in-image cell, in the order the sums add them, of
    the rectangles ``0 .. n_rects - 1`` around every pixel of the tile (0 where none is)."""
    c = tl.zeros([BH, BW], dtype=tl.float64)
    found = tl.zeros([BH, BW], dtype=tl.int1)
    for t in range(0, n_rects):
        a0, a1, b0, b1 = _rect(rect_ptr, t)
        ii = tl.maximum(i + a0, 0)
        jj = tl.maximum(j + b0, 0)
        ok = (ii <= tl.minimum(i + a1, h - 1)) & (jj <= tl.minimum(j + b1, w - 1)) & (found == 0)
        v = tl.load(ptr + ii * w + jj, mask=ok, other=0.0).to(tl.float64)
        c = tl.where(ok, v, c)
        found = found | ok
    return c


@triton.jit
def _first_valid_cell(ptr, vptr, i, j, h, w, rect_ptr, n_rects, BH: tl.constexpr, BW: tl.constexpr):
    """:func:`_first_cell` among the valid cells (``vptr``: 1 for a valid cell): every cell
    looked at, in the order the sums add them."""
    c = tl.zeros([BH, BW], dtype=tl.float64)
    found = tl.zeros([BH, BW], dtype=tl.int1)
    for t in range(0, n_rects):
        a0, a1, b0, b1 = _rect(rect_ptr, t)
        for a in range(a0, a1 + 1):
            ii = i + a
            rows = (ii >= 0) & (ii < h)
            for b in range(b0, b1 + 1):
                jj = j + b
                m = rows & (jj >= 0) & (jj < w) & (found == 0)
                m, v = _cell(ptr, vptr, ii, jj, w, m, True)
                c = tl.where(m, v, c)
                found = found | m
    return c


@triton.jit
def _region_sums_kernel(
    x_ptr,
    valid_ptr,
    rect_ptr,
    start_ptr,
    s1_ptr,
    s2_ptr,
    shift_ptr,
    count_ptr,
    planes,
    h,
    w,
    r0,
    rr,
    regions,
    pad,
    MOMENTS: tl.constexpr,
    VALID: tl.constexpr,
    BH: tl.constexpr,
    BW: tl.constexpr,
):
    plane, k0, col0 = _tile(rr, w, BH, BW)
    i0 = r0 + k0
    k = k0 + tl.arange(0, BH)[:, None]  # rows within the strip
    i = r0 + k
    j = col0 + tl.arange(0, BW)[None, :]
    inside = (k < rr) & (j < w)
    ptr = x_ptr + plane.to(tl.int64) * h * w
    vptr = valid_ptr + plane.to(tl.int64) * h * w
    # every region summed as deviations from one cell of the pixel's own window
    n_rects = tl.load(start_ptr + regions)
    if VALID:
        shift = _first_valid_cell(ptr, vptr, i, j, h, w, rect_ptr, n_rects, BH, BW)
    else:
        shift = _first_cell(ptr, i, j, h, w, rect_ptr, n_rects, BH, BW)
    tl.store(shift_ptr + (plane.to(tl.int64) * rr + k) * w + j, shift, mask=inside)
    # every window inside the image and the tile inside the strip: no masks to form
    full = _interior(i0, col0, h, w, pad, BH, BW) & (k0 + BH <= rr)
    for q in range(0, regions):
        t0 = tl.load(start_ptr + q)
        t1 = tl.load(start_ptr + q + 1)
        if VALID:
            s1, s2, n = _deviation_sums(
                ptr, vptr, i, j, h, w, shift, rect_ptr, t0, t1, BH, BW, MOMENTS, True, True
            )
        elif full:
            s1, s2, n = _deviation_sums(
                ptr, vptr, i, j, h, w, shift, rect_ptr, t0, t1, BH, BW, MOMENTS, False, False
            )
        else:
            s1, s2, n = _deviation_sums(
                ptr, vptr, i, j, h, w, shift, rect_ptr, t0, t1, BH, BW, MOMENTS, True, False
            )
        out = ((q * planes + plane).to(tl.int64) * rr + k) * w + j
        tl.store(s1_ptr + out, s1, mask=inside)
        if MOMENTS >= 2:
            tl.store(s2_ptr + out, s2, mask=inside)
        if VALID:
            tl.store(count_ptr + out, n.to(tl.float64), mask=inside)


def _planes(x: Tensor) -> Tensor:
    return x.detach().reshape(-1, *x.shape[-2:]).contiguous()


def _table(values, dtype: torch.dtype, device: torch.device) -> Tensor:
    """A small lookup table on the device, copied there once per content (the tables
    depend only on the window geometry, the image size and the options)."""
    flat = np.ascontiguousarray(np.asarray(values).reshape(-1), dtype=_NUMPY[dtype])
    return _device_table(flat.tobytes(), dtype, str(device))


_NUMPY = {torch.int32: np.int32, torch.float64: np.float64}


@lru_cache(maxsize=256)
def _device_table(data: bytes, dtype: torch.dtype, device: str) -> Tensor:
    host = torch.from_numpy(np.frombuffer(data, dtype=_NUMPY[dtype]).copy())
    return host.to(device)


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
        with _on(x):
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


_REGION_WARPS = 8
_OS_TILE = (8, 64)  # rows x columns of pixels per program of the decision
_OS_DECISION_WARPS = 8
_OS_TILE_CELLS = 8192  # ring cells x pixels held per program of the statistic


def os_ratio_launch(npad: int, gpu: bool | None = None) -> tuple[int, int, int]:
    """Tile rows, tile columns and warps of :func:`os_ratio` for a ring padded to ``npad``
    cells: on a GPU at most 32 pixels of a row (one warp across them) and
    ``_OS_TILE_CELLS`` cells, about 32 ring values per thread; in Triton's interpreter
    (whose cost is per program, not per lane) tiles of 8 x 64 pixels. ``gpu``: which of
    the two (default: whether CUDA is available)."""
    if not (torch.cuda.is_available() if gpu is None else gpu):
        return 8, 64, 1
    bw = max(1, min(32, _OS_TILE_CELLS // npad))
    return 1, bw, max(1, min(8, npad * bw // 1024))


@contextmanager
def _on(x: Tensor):
    """Launch on ``x``'s GPU (Triton launches on the current device)."""
    if x.is_cuda:
        with torch.cuda.device(x.device):
            yield
    else:
        yield


def os_ratio(
    x: Tensor,
    ring: tuple[int, int],
    offsets: Tensor,
    ranks: np.ndarray,
    scale: np.ndarray,
    threshold: Tensor,
) -> tuple[Tensor, Tensor]:
    """OS-CFAR's statistic ``I / x_(r)`` (exact order statistic, border rule) and mask of
    the float32 image ``x``: ``ring`` is ``(guard, train)``, ``offsets`` ``(N, 2)`` its
    cells, ``ranks`` and ``scale`` (length ``N + 1``) the rank and border factor of each
    ring count."""
    planes = _planes(x)
    p, h, w = planes.shape
    out = torch.empty_like(planes)
    mask = torch.empty(planes.shape, dtype=torch.bool, device=planes.device)
    n = offsets.shape[0]
    npad = triton.next_power_of_2(n)
    dr = np.zeros(npad, dtype=np.int32)
    dc = np.full(npad, -(1 << 30), dtype=np.int32)  # padding: far outside every image
    dr[:n], dc[:n] = offsets[:, 0].numpy(), offsets[:, 1].numpy()
    if planes.numel():
        bh, bw, warps = os_ratio_launch(npad)
        with _on(x):
            _os_ratio_kernel[(p * triton.cdiv(h, bh) * triton.cdiv(w, bw),)](
                planes,
                _table(dr, torch.int32, x.device),
                _table(dc, torch.int32, x.device),
                _table(ranks, torch.int32, x.device),
                _table(scale, torch.float64, x.device),
                threshold.reshape(1).to(torch.float32),
                out,
                mask.view(torch.int8),
                h,
                w,
                ring[0],
                ring[0] + ring[1],
                NP=npad,
                BH=bh,
                BW=bw,
                num_warps=warps,
                enable_fp_fusion=False,
            )
    return out.view(x.shape), mask.view(x.shape)


def os_decision(
    x: Tensor,
    ring: tuple[int, int],
    offsets: Tensor,
    ranks: np.ndarray,
    scale: np.ndarray,
    threshold: Tensor,
) -> Tensor:
    """OS-CFAR's mask alone, by counting (the arguments of :func:`os_ratio`; ``offsets``
    is not needed: the ring is walked row by row)."""
    planes = _planes(x)
    p, h, w = planes.shape
    mask = torch.empty(planes.shape, dtype=torch.bool, device=planes.device)
    if planes.numel():
        bh, bw = _OS_TILE
        with _on(x):
            _os_decision_kernel[(p * triton.cdiv(h, bh) * triton.cdiv(w, bw),)](
                planes,
                _table(ranks, torch.int32, x.device),
                _table(scale, torch.float64, x.device),
                threshold.reshape(1).to(torch.float32),
                mask.view(torch.int8),
                h,
                w,
                ring[0],
                ring[0] + ring[1],
                BH=bh,
                BW=bw,
                num_warps=_OS_DECISION_WARPS,
                enable_fp_fusion=False,
            )
    return mask.view(x.shape)


def region_sums(
    x: Tensor,
    regions: list[list[tuple[int, int, int, int]]],
    r: int,
    rr: int,
    moments: int,
    valid: Tensor | None = None,
) -> tuple[Tensor, Tensor | None, Tensor, Tensor | None]:
    """Window sums of the float32 image ``x`` ``(B, C, H, W)`` for output rows ``r .. r + rr
    - 1``: for each region (a list of disjoint rectangles ``(r0, r1, c0, c1)`` of offsets,
    inclusive), ``s1 = sum(x - shift)`` and (``moments >= 2``) ``s2 = sum((x - shift)^2)``
    over its in-image cells (and, with ``valid``, a bool mask of ``x``'s shape, only the
    valid ones, which it also counts), each cell added directly in float64 in a fixed order
    (no integral image, no subtraction of overlapping windows).

    ``shift`` is per pixel, the same for all its regions: the value of the first in-image
    (valid) cell of its rectangles (in the order they are summed; 0 where none is). Sums
    of deviations from a cell of the pixel's own window keep the variance ``s2 / n - (s1 /
    n)^2`` precise whatever lies elsewhere in the image (a plane's mean, moved by a bright
    target far away, made it cancel), and a region of equal cells has ``s1 = s2 = 0``
    exactly when the cell is its own.

    Returns float64 ``(K, B, C, rr, W)`` for ``s1`` and ``s2`` (``None`` without), the
    shift ``(B, C, rr, W)`` and, with ``valid``, the counts ``(K, B, C, rr, W)`` (else
    ``None``)."""
    b, c, h, w = x.shape
    planes = _planes(x)
    shape = (len(regions), b, c, rr, w)
    s1 = torch.empty(shape, dtype=torch.float64, device=x.device)
    s2 = torch.empty(shape, dtype=torch.float64, device=x.device) if moments >= 2 else None
    count = None if valid is None else torch.empty(shape, dtype=torch.float64, device=x.device)
    shift = torch.zeros((b, c, rr, w), dtype=torch.float64, device=x.device)
    if valid is None:  # not read: a placeholder of the kernel's type
        flags = torch.zeros(1, dtype=torch.int8, device=x.device)
    else:
        flags = _planes(valid.expand_as(x)).to(torch.int8)
    rects = [rect for region in regions for rect in region]
    starts = np.cumsum([0] + [len(region) for region in regions])
    if s1.numel():
        bh, bw = _CA_TILE
        grid = (planes.shape[0] * triton.cdiv(rr, bh) * triton.cdiv(w, bw),)
        with _on(x):
            _region_sums_kernel[grid](
                planes,
                flags,  # not read without a mask
                _table(rects, torch.int32, x.device),
                _table(starts, torch.int32, x.device),
                s1,
                s1 if s2 is None else s2,  # not written with one moment
                shift,
                s1 if count is None else count,  # not written without a mask
                planes.shape[0],
                h,
                w,
                r,
                rr,
                len(regions),
                max(max(abs(v) for v in rect) for rect in rects),
                MOMENTS=moments,
                VALID=valid is not None,
                BH=bh,
                BW=bw,
                num_warps=region_warps(valid is not None),
                enable_fp_fusion=False,
            )
    return s1, s2, shift, count


def region_warps(valid: bool) -> int:
    """:func:`region_sums`' warps per program; with a mask (a count, the valid flags, the
    first valid cell's search) twice as many, half the pixels per thread, so that the
    registers hold them without spilling (58 and 60 registers for sm_90, against 52 and
    68 bytes spilled with as many warps as without a mask)."""
    return _REGION_WARPS * (2 if valid else 1)
