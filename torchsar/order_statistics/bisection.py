"""Exact ring order statistic by bit-wise bisection of tile ranks (small rings).

Algorithm (exact, memory bounded, no per-pixel Python loop):

1. The image is cut into tiles (planes x rows x columns, with the ring's halo) of at most
   65 535 cells (fewer for large rings, so the ``N x tile`` compare buffer stays ~4 MB,
   within the last-level cache); the **ranks** of the cell values inside a tile then fit in
   ``B <= 16`` bits. Ranks are ordinal (ties broken arbitrarily but consistently), so the ``k``-th
   smallest rank points to the ``k``-th smallest value. Missing (outside / invalid) cells
   get rank ``2^B - 1`` and are never counted.
2. Every pixel bisects its answer bit by bit: a candidate rank ``t`` is kept or raised by
   counting the ring cells with rank ``<= t``. The ring cells of every pixel are laid out as
   a contiguous ``(N, tile)`` uint8 buffer (strided views of the padded tile, one copy), so
   a step is one uint8 compare against the per-pixel threshold and one uint8 column sum.
   The top 8 bits are decided on the high bytes; then cells whose high byte differs from the
   pixel's answer are remapped to "always below" (0) or "never counted" (255), so the last
   ``B - 8`` steps also run on uint8.
3. The final rank indexes the tile's sorted values: the result is an input value, bit-exact.

The work per pixel is ``B N`` byte compares and sums (``N`` ring cells), vectorised over the
tile and independent of the data: the fastest choice for small rings, but it grows with the
ring's area, so large rings go to :mod:`torchsar.order_statistics.histogram`. All per-step
buffers are allocated once per call: on CPU, fresh large temporaries (page faults) cost more
than the arithmetic.

References:
    Rohling, H., IEEE TAES 19(4), 608-621, 1983, doi:10.1109/TAES.1983.309350 (OS-CFAR).
"""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar.order_statistics.sorting import argsort_rows
from torchsar.windows import Ring

__all__ = ["CELL_BUDGET", "bisection_select", "fits"]

CELL_BUDGET = 65535  # cells per tile, so ranks fit 16 bits
_COMPARE_BUDGET = 1 << 22  # bytes of the per-step compare buffer (N x tile): measured best


def bisection_select(planes: Tensor, ring: Ring, kk: Tensor, vm: Tensor | None) -> Tensor:
    """The ``kk``-th smallest counted ring value at every pixel of ``planes`` ``(P, H, W)``.

    ``kk`` ``(P, H, W)`` holds 1-based ranks, at most the pixel's counted ring cells (``0``
    gives ``0``); ``vm`` an optional bool mask of counted cells, same shape. The ring must
    fit a 16-bit tile: ``(2(g+t)+1)^2 <= 32767`` (see :func:`fits`).
    """
    out = torch.zeros_like(planes)
    p, h, w = planes.shape
    o = ring.outer
    tiles = _tiles(p, h, w, o, ring.n)
    longest = max(_tile_length(t, o) for t in tiles)
    ws = _Workspace(ring.n, longest, planes.device)
    for tile in tiles:
        _select_tile(planes, ring, kk, vm, out, tile, ws)
    return out


def fits(ring: Ring) -> bool:
    """Whether a tile with the ring's halo fits the 16-bit rank budget."""
    return ring.extent**2 <= CELL_BUDGET // 2


def _tiles(p: int, h: int, w: int, o: int, n: int) -> list[tuple[int, int, int, int, int, int]]:
    """Output tiles ``(p0, p1, y0, y1, x0, x1)`` whose padded input stays within budget."""
    budget = max((2 * o + 1) ** 2 * 2, min(CELL_BUDGET, _COMPARE_BUDGET // max(n, 1)))
    wp = w + 2 * o
    tw = w if wp * (2 * o + 2) <= budget else max(1, budget // (2 * (2 * o + 2)) - 2 * o)
    th = max(1, min(h, budget // (tw + 2 * o) - 2 * o))
    pc = max(1, budget // ((h + 2 * o) * (tw + 2 * o))) if th == h else 1
    return [
        (p0, min(p, p0 + pc), y0, min(h, y0 + th), x0, min(w, x0 + tw))
        for p0 in range(0, p, pc)
        for y0 in range(0, h, th)
        for x0 in range(0, w, tw)
    ]


def _tile_length(tile: tuple[int, ...], o: int) -> int:
    """Number of flat positions bisected for a tile (pixels plus the junk between rows)."""
    p0, p1, y0, y1, x0, x1 = tile
    wp, hp = x1 - x0 + 2 * o, y1 - y0 + 2 * o
    return (p1 - p0 - 1) * hp * wp + (y1 - y0 - 1) * wp + (x1 - x0)


def _rank_bits(cells: int) -> int:
    """Bits of the tile ranks: ``cells`` real ranks plus the "missing" rank ``2^B - 1``."""
    return max(9, cells.bit_length())


def _missing(cells: int) -> int:
    """The rank of missing cells: all ones, so its high byte is 255 (never counted)."""
    return (1 << _rank_bits(cells)) - 1


def _tile_ranks(
    planes: Tensor, vm: Tensor | None, tile: tuple[int, ...], o: int
) -> tuple[Tensor, Tensor]:
    """Padded int32 rank image ``(P, th + 2o, tw + 2o)`` of a tile (missing cells
    ``2^B - 1``, see :func:`_missing`) and the tile's sorted counted values."""
    p0, p1, y0, y1, x0, x1 = tile
    h, w = planes.shape[-2:]
    ya, yb, xa, xb = max(0, y0 - o), min(h, y1 + o), max(0, x0 - o), min(w, x1 + o)
    vals = planes[p0:p1, ya:yb, xa:xb]
    keep = None if vm is None else vm[p0:p1, ya:yb, xa:xb]
    flat = vals.reshape(-1) if keep is None else vals[keep]
    order = argsort_rows(flat)
    srt = flat[order]
    rank = torch.empty(flat.numel(), dtype=torch.int32, device=flat.device)
    rank[order] = torch.arange(flat.numel(), dtype=torch.int32, device=flat.device)
    shape = (p1 - p0, y1 - y0 + 2 * o, x1 - x0 + 2 * o)
    pad = torch.full(shape, _missing(flat.numel()), dtype=torch.int32, device=flat.device)
    region = pad[:, ya - y0 + o : yb - y0 + o, xa - x0 + o : xb - x0 + o]
    if keep is None:
        region.copy_(rank.view(vals.shape))
    else:
        region[keep] = rank
    return pad, srt


def _ring_blocks(ring: Ring) -> list[tuple[int, int, int, int]]:
    """The ring as 4 rectangles ``(dy0, rows, dx0, cols)`` of offsets: top and bottom bands
    (full width), left and right pieces of the guard rows."""
    g, t, o = ring.guard, ring.train, ring.outer
    return [
        (-o, t, -o, 2 * o + 1),
        (g + 1, t, -o, 2 * o + 1),
        (-g, 2 * g + 1, -o, t),
        (-g, 2 * g + 1, g + 1, t),
    ]


def _views(flat: Tensor, base: int, length: int, wp: int, ring: Ring) -> list[Tensor]:
    """Strided ``(rows, cols, L)`` views of ``flat`` for each ring block (no copy)."""
    return [
        flat.as_strided((nr, nc, length), (wp, 1, 1), base + dy * wp + dx)
        for dy, nr, dx, nc in _ring_blocks(ring)
    ]


class _Workspace:
    """Buffers reused by every tile of one call: fresh large allocations (page faults) cost
    more than the uint8 arithmetic, so every step writes into these with ``out=``."""

    def __init__(self, n: int, length: int, device: torch.device) -> None:
        self.cells = torch.empty((n, length), dtype=torch.uint8, device=device)
        self.flags = torch.empty((n, length), dtype=torch.bool, device=device)
        acc = torch.uint8 if n <= 255 else torch.int16
        self.count = torch.empty(length, dtype=acc, device=device)
        self.kk = torch.empty(length, dtype=acc, device=device)
        self.less = torch.empty(length, dtype=torch.bool, device=device)
        self.thr = torch.empty(length, dtype=torch.uint8, device=device)
        self.prefix = torch.empty(length, dtype=torch.int32, device=device)
        self.tmp = torch.empty(length, dtype=torch.int32, device=device)

    def take(self, length: int) -> tuple[Tensor, ...]:
        """Views of the first ``length`` positions of every buffer."""
        return tuple(
            b[..., :length]
            for b in (
                self.cells,
                self.flags,
                self.count,
                self.kk,
                self.less,
                self.thr,
                self.prefix,
                self.tmp,
            )
        )


def _bisect(bufs: tuple[Tensor, ...], bits: range, shift: int, low: bool) -> None:
    """Decide the given bits of ``prefix`` (in place): keep bit ``b`` clear when at least
    ``kk`` cells are ``<=`` the candidate ``prefix + 2^b - 1`` -- its high part
    (``>> shift``) against the high-byte cells, or its low ``shift`` bits against the
    remapped low cells."""
    cells, flags, count, kk, less, thr, prefix, tmp = bufs
    for b in bits:
        torch.add(prefix, (1 << b) - 1, out=tmp)
        if low:
            tmp.bitwise_and_((1 << shift) - 1)
        else:
            tmp.bitwise_right_shift_(shift)
        thr.copy_(tmp)
        torch.le(cells, thr, out=flags)
        torch.sum(flags.view(torch.uint8), 0, dtype=count.dtype, out=count)
        torch.lt(count, kk, out=less)
        tmp.copy_(less)
        prefix.add_(tmp, alpha=1 << b)


def _gather_cells(views: list[Tensor], cells: Tensor) -> None:
    """Copy the strided ring views into the contiguous ``(N, L)`` cell buffer."""
    start = 0
    for v in views:
        size = v.shape[0] * v.shape[1]
        cells[start : start + size].view(v.shape).copy_(v)
        start += size


def _remap_low(bufs: tuple[Tensor, ...], lv: list[Tensor], shift: int) -> None:
    """Replace the high-byte cells by low-byte cells relative to each pixel's decided high
    byte ``K = prefix >> shift``: the low bits where the cell's high byte is ``K``, 0
    ("always below") where smaller, 255 ("never counted") where larger (the low steps test at
    most ``2^shift - 2``). uint8 ops into the workspace only."""
    cells, flags, _, _, _, thr, prefix, tmp = bufs
    torch.bitwise_right_shift(prefix, shift, out=tmp)
    thr.copy_(tmp)
    torch.gt(cells, thr, out=flags)
    above = flags.clone()
    torch.ge(cells, thr, out=flags)
    _gather_cells(lv, cells)
    torch.minimum(cells, flags.view(torch.uint8).neg_(), out=cells)
    cells.bitwise_or_(above.view(torch.uint8).neg_())


def _select_tile(
    planes: Tensor,
    ring: Ring,
    kk: Tensor,
    vm: Tensor | None,
    out: Tensor,
    tile: tuple[int, ...],
    ws: _Workspace,
) -> None:
    """Bisect the ranks of one tile and write the selected values into ``out``."""
    p0, p1, y0, y1, x0, x1 = tile
    o = ring.outer
    ranks, srt = _tile_ranks(planes, vm, tile, o)
    pc, hp, wp = ranks.shape
    th, tw = y1 - y0, x1 - x0
    base = o * wp + o
    length = (pc - 1) * hp * wp + (th - 1) * wp + tw
    bufs = ws.take(length)
    k_flat = torch.ones(pc * hp * wp, dtype=bufs[3].dtype, device=ranks.device)
    k_flat.view(pc, hp, wp)[:, o : o + th, o : o + tw] = kk[p0:p1, y0:y1, x0:x1].to(k_flat.dtype)
    bufs[3].copy_(k_flat[base : base + length])
    bits = _rank_bits(srt.numel())
    shift = bits - 8
    high = (ranks >> shift).to(torch.uint8).reshape(-1)
    bufs[6].zero_()
    _gather_cells(_views(high, base, length, wp, ring), bufs[0])
    _bisect(bufs, range(bits - 1, shift - 1, -1), shift, False)
    low = (ranks & ((1 << shift) - 1)).to(torch.uint8).reshape(-1)
    _remap_low(bufs, _views(low, base, length, wp, ring), shift)
    _bisect(bufs, range(shift - 1, -1, -1), shift, True)
    full = torch.zeros(pc * hp * wp, dtype=torch.int64, device=ranks.device)
    full[base : base + length] = bufs[6].clamp(max=max(srt.numel() - 1, 0))
    sel = full.view(pc, hp, wp)[:, o : o + th, o : o + tw]
    vals = srt[sel] if srt.numel() else torch.zeros(sel.shape, dtype=out.dtype, device=out.device)
    kt = kk[p0:p1, y0:y1, x0:x1]
    out[p0:p1, y0:y1, x0:x1] = torch.where(kt > 0, vals, torch.zeros_like(vals))
