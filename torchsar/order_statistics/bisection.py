"""Exact ring order statistic by bit-wise bisection of piece ranks (small rings).

Algorithm (exact, memory bounded, no per-pixel Python loop):

1. The planes are cut into pieces (rows x columns of one plane, with the ring's halo) of at
   most 65 535 cells (on CPU fewer for large rings, so the ``N x positions`` compare buffer
   stays ~4 MB, within the last-level cache); the **ranks** of the cell values inside a
   piece then fit in ``B <= 16`` bits. Ranks are ordinal (ties broken arbitrarily but
   consistently), so the ``k``-th smallest rank points to the ``k``-th smallest value.
   Missing (outside / invalid) cells get rank ``2^B - 1`` and are never counted.
2. Every pixel bisects its answer bit by bit: a candidate rank ``t`` is kept or raised by
   counting the ring cells with rank ``<= t``. The ring cells of every pixel of a group of
   pieces are laid out as a contiguous ``(N, positions)`` uint8 buffer (strided views of the
   stacked pieces, one copy), so a step is one uint8 compare against the per-pixel
   threshold and one uint8 column sum. The top 8 bits are decided on the high bytes; then
   cells whose high byte differs from the pixel's answer are remapped to "always below" (0)
   or "never counted" (255), so the last ``B - 8`` steps also run on uint8.
3. The final rank indexes its piece's sorted values: the result is an input value,
   bit-exact.

The work per pixel is ``B N`` byte compares and sums (``N`` ring cells), vectorised over a
group of pieces and independent of the data: the fastest choice for small rings, but it
grows with the ring's area, so large rings go to :mod:`torchsar.order_statistics.histogram`.
A group holds as many pieces as the compare buffer's budget allows: ~4 MB on CPU (cache),
256 MB on other devices (a GPU then bisects a whole batch in a few dozen launches per
step instead of one per piece). All per-step buffers are allocated once per call: on CPU,
fresh large temporaries (page faults) cost more than the arithmetic.

References:
    Rohling, H., IEEE TAES 19(4), 608-621, 1983, doi:10.1109/TAES.1983.309350 (OS-CFAR).
"""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar.order_statistics.sorting import argsort_rows
from torchsar.windows import Ring

__all__ = ["CELL_BUDGET", "DEVICE_COMPARE_BUDGET", "bisection_select", "fits"]

CELL_BUDGET = 65535  # cells per piece, so ranks fit 16 bits
_COMPARE_BUDGET = 1 << 22  # CPU: bytes of the per-step N x positions buffer: measured best
DEVICE_COMPARE_BUDGET = 1 << 28  # other devices: the same buffer, large groups, few launches


def bisection_select(planes: Tensor, ring: Ring, kk: Tensor, vm: Tensor | None) -> Tensor:
    """The ``kk``-th smallest counted ring value at every pixel of ``planes`` ``(P, H, W)``.

    ``kk`` ``(P, H, W)`` holds 1-based ranks, at most the pixel's counted ring cells (``0``
    gives ``0``); ``vm`` an optional bool mask of counted cells, same shape. The ring must
    fit a 16-bit piece: ``(2(g+t)+1)^2 <= 32767`` (see :func:`fits`).
    """
    p, h, w = planes.shape
    o = ring.outer
    budget = _COMPARE_BUDGET if planes.device.type == "cpu" else DEVICE_COMPARE_BUDGET
    th, tw = _piece_shape(h, w, o, ring.n, budget)
    pieces, keep, k = _cut(planes, vm, kk, th, tw, o)
    hp, wp = th + 2 * o, tw + 2 * o
    group = max(1, budget // max(ring.n, 1) // (hp * wp))
    ws = _Workspace(ring.n, _length(min(group, len(pieces)), hp, wp, o), planes.device)
    out = torch.empty((len(pieces), th, tw), dtype=planes.dtype, device=planes.device)
    for g0 in range(0, len(pieces), group):
        g1 = min(len(pieces), g0 + group)
        ranks, srt = _piece_ranks(pieces[g0:g1], keep[g0:g1])  # per group: in cache on CPU
        out[g0:g1] = _select_group(ranks, srt, k[g0:g1], ring, ws)
    return _uncut(out, p, h, w)


def fits(ring: Ring) -> bool:
    """Whether a piece with the ring's halo fits the 16-bit rank budget."""
    return ring.extent**2 <= CELL_BUDGET // 2


def _piece_shape(h: int, w: int, o: int, n: int, budget: int) -> tuple[int, int]:
    """Output rows and columns ``(th, tw)`` of a piece whose padded cells stay within the
    cell budget (and, on CPU, the compare budget): full-width strips where a strip of a
    few rows fits, else narrower pieces."""
    cells = max((2 * o + 1) ** 2 * 2, min(CELL_BUDGET, budget // max(n, 1)))
    wp = w + 2 * o
    tw = w if wp * (2 * o + 2) <= cells else max(1, cells // (2 * (2 * o + 2)) - 2 * o)
    th = max(1, min(h, cells // (tw + 2 * o) - 2 * o))
    return th, tw


def _length(g: int, hp: int, wp: int, o: int) -> int:
    """Number of flat positions bisected for ``g`` stacked pieces (pixels plus the junk
    between rows and pieces)."""
    return (g - 1) * hp * wp + (hp - 2 * o - 1) * wp + (wp - 2 * o)


def _cut(
    planes: Tensor, vm: Tensor | None, kk: Tensor, th: int, tw: int, o: int
) -> tuple[Tensor, Tensor, Tensor]:
    """The pieces ``(T, th + 2o, tw + 2o)`` of every plane (plane-major, then rows, then
    columns; ``T = P ny nx``) with their halos: the values, which cells are counted (in the
    image and valid) and the ranks ``kk`` (0 outside the image; only a piece's interior is
    used)."""
    p, h, w = planes.shape
    ny, nx = -(-h // th), -(-w // tw)
    shape = (p, ny * th + 2 * o, nx * tw + 2 * o)
    hp, wp = th + 2 * o, tw + 2 * o

    def pieces(inside: Tensor | bool, dtype: torch.dtype) -> Tensor:
        full = torch.zeros(shape, dtype=dtype, device=planes.device)
        full[:, o : o + h, o : o + w] = inside
        return full.unfold(1, hp, th).unfold(2, wp, tw).reshape(-1, hp, wp)

    keep = pieces(True if vm is None else vm, torch.bool)
    return pieces(planes, planes.dtype), keep, pieces(kk, kk.dtype)


def _uncut(out: Tensor, p: int, h: int, w: int) -> Tensor:
    """The pieces' interiors ``(T, th, tw)`` (as :func:`_cut` orders them) back to
    ``(P, H, W)``."""
    _, th, tw = out.shape
    ny, nx = -(-h // th), -(-w // tw)
    full = out.view(p, ny, nx, th, tw).permute(0, 1, 3, 2, 4).reshape(p, ny * th, nx * tw)
    return full[:, :h, :w]


def _rank_bits(cells: int) -> int:
    """Bits of the piece ranks: ``cells`` real ranks plus the "missing" rank ``2^B - 1``."""
    return max(9, cells.bit_length())


def _missing(cells: int) -> int:
    """The rank of missing cells: all ones, so its high byte is 255 (never counted)."""
    return (1 << _rank_bits(cells)) - 1


def _piece_ranks(pieces: Tensor, keep: Tensor) -> tuple[Tensor, Tensor]:
    """int32 rank of every cell within its piece ``(T, hp, wp)`` (missing cells
    ``2^B - 1``, see :func:`_missing`) and each piece's values sorted ``(T, hp wp)``
    (counted cells first)."""
    t, hp, wp = pieces.shape
    cells = hp * wp
    counted = keep.reshape(t, cells)
    vals = torch.where(counted, pieces.reshape(t, cells), torch.inf)  # missing sort last
    order = argsort_rows(vals)
    srt = vals.gather(1, order)
    rank = torch.empty((t, cells), dtype=torch.int32, device=pieces.device)
    pos = torch.arange(cells, dtype=torch.int32, device=pieces.device)
    rank.scatter_(1, order, pos.expand(t, cells))
    rank.masked_fill_(~counted, _missing(cells))
    return rank.view(t, hp, wp), srt


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
    """Buffers reused by every group of one call: fresh large allocations (page faults) cost
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


def _select_group(ranks: Tensor, srt: Tensor, k: Tensor, ring: Ring, ws: _Workspace) -> Tensor:
    """Bisect the ranks of a group of pieces ``(g, hp, wp)`` at their interior pixels (ranks
    ``k``, cut like the pieces): the selected values ``(g, th, tw)``."""
    g, hp, wp = ranks.shape
    o = ring.outer
    th, tw = hp - 2 * o, wp - 2 * o
    base = o * wp + o
    length = _length(g, hp, wp, o)
    bufs = ws.take(length)
    bufs[3].copy_(k.reshape(-1)[base : base + length])  # junk positions: any rank, unused
    bits = _rank_bits(hp * wp)
    shift = bits - 8
    high = (ranks >> shift).to(torch.uint8).reshape(-1)
    bufs[6].zero_()
    _gather_cells(_views(high, base, length, wp, ring), bufs[0])
    _bisect(bufs, range(bits - 1, shift - 1, -1), shift, False)
    low = (ranks & ((1 << shift) - 1)).to(torch.uint8).reshape(-1)
    _remap_low(bufs, _views(low, base, length, wp, ring), shift)
    _bisect(bufs, range(shift - 1, -1, -1), shift, True)
    full = torch.zeros(g * hp * wp, dtype=torch.int64, device=ranks.device)
    full[base : base + length] = bufs[6].clamp(max=hp * wp - 1)
    sel = full.view(g, hp, wp)[:, o : o + th, o : o + tw].reshape(g, th * tw)
    vals = srt.gather(1, sel).view(g, th, tw)
    return torch.where(k[:, o : o + th, o : o + tw] > 0, vals, torch.zeros_like(vals))
