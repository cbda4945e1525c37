"""Exact ring order statistic by a sliding two-level histogram of ranks (large rings).

The image is cut into square tiles of side ``s >= 2o + 1`` (``o`` the ring's outer
half-width). Inside a tile (with its ``o``-cell halo) every cell gets its ordinal rank; cells
outside the image or marked invalid are ``+inf`` and so rank after every counted cell. For
each output row of every tile a histogram of the ranks of its ring is kept, at two levels:
``F`` fine bins per coarse bin, ``C * F >= M`` ranks (``C, F ~ sqrt(M)``, ``M`` the tile's
cell count). Moving one pixel to the right changes the ring by four columns (the outer box
gains one and loses one; the guard box likewise), so an update costs ``4 (g + t) + 4`` scatter
adds per level, and the ``k``-th smallest rank is found by a search over ``C`` coarse counts
then over the ``F`` fine counts of one coarse bin. The work per pixel therefore grows
linearly with the ring side, not with its area; all rows of all tiles of a group move
together, so a step is a handful of vectorised ops whatever the batch.

Huang, Yang & Tang, IEEE TASSP 27(1), 13-18, 1979, doi:10.1109/TASSP.1979.1163188 (sliding
histogram); Perreault & Hebert, IEEE TIP 16(9), 2389-2394, 2007,
doi:10.1109/TIP.2007.902329 (two-level histograms).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar.order_statistics.sorting import argsort_rows
from torchsar.windows import Ring

__all__ = ["histogram_select"]

HIST_BUDGET = 1 << 22  # histogram cells per group of tiles (kept cache sized)


@dataclass(frozen=True)
class _Tiling:
    """Square output tiles of side ``side`` over ``(rows, cols)`` tiles, halo ``o``."""

    side: int
    rows: int
    cols: int
    o: int

    @property
    def span(self) -> int:
        """Side of a tile with its halo."""
        return self.side + 2 * self.o

    @property
    def cells(self) -> int:
        """Cells per tile with its halo (the size of the rank space)."""
        return self.span**2


@dataclass(frozen=True)
class _Bins:
    """Two-level histogram layout: ``fine`` bins per coarse bin, ``coarse`` bins; a row is
    ``[coarse * fine fine bins | one zero bin | coarse bins]``."""

    fine: int
    coarse: int

    @staticmethod
    def for_ranks(m: int) -> _Bins:
        f = math.isqrt(max(m - 1, 0)) + 1
        return _Bins(f, -(-m // f))

    @property
    def width(self) -> int:
        return self.fine * self.coarse + 1 + self.coarse

    @property
    def dtype(self) -> torch.dtype:
        """Counts stay below ``fine + 1``; uint8 arithmetic wraps exactly for removals."""
        return torch.uint8 if self.fine <= 255 else torch.int16


def histogram_select(planes: Tensor, ring: Ring, kk: Tensor, vm: Tensor | None) -> Tensor:
    """The ``kk``-th smallest counted ring value at every pixel of ``planes`` ``(P, H, W)``.

    ``kk`` ``(P, H, W)`` holds 1-based ranks, at most the pixel's counted ring cells (``0``
    gives ``0``); ``vm`` an optional bool mask of counted cells, same shape. Tiles are
    ranked and swept in groups whose histograms fit :data:`HIST_BUDGET`, so the memory
    beyond the input and output is bounded.
    """
    p, h, w = planes.shape
    o = ring.outer
    side = max(2 * o + 1, 8)
    t = _Tiling(side, -(-h // side), -(-w // side), o)
    tiles = _tile_view(planes, vm, t)
    bins = _Bins.for_ranks(t.cells)
    u = p * t.rows * t.cols
    group = max(1, HIST_BUDGET // (t.side * bins.width))
    hist = torch.empty((min(u, group), t.side, bins.width), dtype=bins.dtype, device=planes.device)
    k = _to_tiles(kk.clamp_min(1), t).transpose(0, 1).contiguous()  # (x, U, y): contiguous steps
    found = torch.empty_like(k)
    vals = torch.empty((u, t.side * t.side), dtype=planes.dtype, device=planes.device)
    for u0 in range(0, u, group):
        u1 = min(u, u0 + group)
        ui = torch.arange(u0, u1, device=planes.device)
        rest = ui % (t.rows * t.cols)
        cells = (
            tiles[ui // (t.rows * t.cols), rest // t.cols, rest % t.cols]
            .transpose(-1, -2)
            .reshape(u1 - u0, -1)
        )
        order = argsort_rows(cells).to(planes.device)
        ranks = torch.empty_like(order)
        ranks.scatter_(1, order, torch.arange(t.cells, device=planes.device).expand_as(order))
        images = (ranks, ranks // bins.fine + (bins.fine * bins.coarse + 1))
        _sweep_group(hist[: u1 - u0], images, k[:, u0:u1], found[:, u0:u1], ring, t, bins)
        at = found[:, u0:u1].transpose(0, 1).reshape(u1 - u0, -1).clamp_(max=t.cells - 1)
        vals[u0:u1] = cells.gather(1, order.gather(1, at))
    out = _from_tiles(vals, t, p, h, w)
    return torch.where(kk > 0, out, torch.zeros_like(out))


def _tile_view(planes: Tensor, vm: Tensor | None, t: _Tiling) -> Tensor:
    """``(P, rows, cols, span, span)`` view of every tile with its halo over the padded
    image; missing cells are ``+inf``."""
    h, w = planes.shape[-2:]
    if vm is not None:
        planes = planes.masked_fill(~vm, torch.inf)
    extra_h, extra_w = t.rows * t.side - h, t.cols * t.side - w
    pad = torch.nn.functional.pad(planes, (t.o, t.o + extra_w, t.o, t.o + extra_h), value=torch.inf)
    return pad.unfold(1, t.span, t.side).unfold(2, t.span, t.side)


def _to_tiles(kk: Tensor, t: _Tiling) -> Tensor:
    """Per-pixel ranks as ``(U, side (x), side (y))`` long, padded with 1."""
    p, h, w = kk.shape
    k = torch.nn.functional.pad(kk, (0, t.cols * t.side - w, 0, t.rows * t.side - h), value=1)
    k = k.view(p, t.rows, t.side, t.cols, t.side).permute(0, 1, 3, 4, 2)
    return k.reshape(-1, t.side, t.side).long()


def _from_tiles(vals: Tensor, t: _Tiling, p: int, h: int, w: int) -> Tensor:
    """Inverse of :func:`_to_tiles` for the ``(U, side * side)`` results (x-major)."""
    v = vals.view(p, t.rows, t.cols, t.side, t.side).permute(0, 1, 4, 2, 3)
    return v.reshape(p, t.rows * t.side, t.cols * t.side)[:, :h, :w]


def _sweep_group(
    hist: Tensor,
    images: tuple[Tensor, Tensor],
    k: Tensor,
    found: Tensor,
    ring: Ring,
    t: _Tiling,
    bins: _Bins,
) -> None:
    """Slide every row's ring histogram across its tile; ``k`` and ``found`` are
    ``(x, U, y)``: the 1-based ranks asked and the 0-based ranks found."""
    g, o = ring.guard, ring.outer
    hist.zero_()
    one = torch.ones((1, 1, 1), dtype=hist.dtype, device=hist.device)
    minus = torch.full((1, 1, 1), -1, dtype=torch.int16, device=hist.device).to(hist.dtype)
    for col in range(2 * o + 1):  # the ring of the first pixel of every row
        if o - g <= col <= o + g:
            _scatter(hist, images, t, col, 0, o - g, one)
            _scatter(hist, images, t, col, o + g + 1, o - g, one)
        else:
            _scatter(hist, images, t, col, 0, 2 * o + 1, one)
    for x in range(t.side):
        if x:
            _scatter(hist, images, t, x + 2 * o, 0, 2 * o + 1, one)
            _scatter(hist, images, t, x - 1, 0, 2 * o + 1, minus)
            _scatter(hist, images, t, x + o + g, o - g, 2 * g + 1, minus)
            _scatter(hist, images, t, x - 1 + o - g, o - g, 2 * g + 1, one)
        found[x] = _select(hist, k[x].unsqueeze(-1), bins)


def _scatter(
    hist: Tensor, images: tuple[Tensor, ...], t: _Tiling, col: int, row: int, n: int, sign: Tensor
) -> None:
    """Add ``sign`` to both levels for the ``n`` cells of halo column ``col`` starting at
    row ``r + row``, for every output row ``r`` of every tile (strided views, no copy)."""
    for img in images:
        view = img.as_strided(
            (img.shape[0], t.side, n), (t.cells, 1, 1), img.storage_offset() + col * t.span + row
        )
        hist.scatter_add_(2, view, sign.expand(view.shape))


def _select(hist: Tensor, k: Tensor, bins: _Bins) -> Tensor:
    """The ``k``-th smallest rank ``(U, rows)`` from the two-level histograms ``hist``."""
    f, c = bins.fine, bins.coarse
    cum = hist[..., f * c :].cumsum(-1)  # leading zero bin, then the coarse counts
    i = torch.searchsorted(cum, k)
    below = cum.gather(-1, i - 1)
    fine = hist[..., : f * c].unflatten(-1, (c, f))
    seg = fine.gather(-2, (i - 1).unsqueeze(-1).expand(*i.shape, f)).squeeze(-2)
    j = torch.searchsorted(seg.cumsum(-1), k - below)
    return ((i - 1) * f + j).squeeze(-1)
