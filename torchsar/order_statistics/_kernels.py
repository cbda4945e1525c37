"""numba kernel of the exact ring order statistic: a rank bitset per pixel (CPU).

Per plane, the image is cut into tiles whose cells, with the ring's halo, are **ranked**:
the values become order-preserving integer keys (the float bits with the sign handled, 32
bits for float32 and 64 for float64; ``-0.0`` as ``+0.0``; cells outside the image or not
valid are ``+inf``), sorted by a stable LSD radix sort (8-bit digits; a digit equal over
the whole tile is skipped), so every cell has a distinct rank in ``[0, M)``. The ring of
the current pixel is a set of ranks held as a bitset of ``M`` bits; the ``k``-th smallest
rank indexes the tile's sorted values: the result is an input value, exact. Missing cells
rank after every counted cell, so they are never selected for ``k`` up to the pixel's count
of counted cells. Two sweeps keep the bitset up to date, with the same results:

- **column bitsets** (:func:`_sweep_columns`, rings reaching at most
  :data:`COLUMNS_MAX_OUTER` cells from the pixel): small tiles (about
  :data:`COLUMN_TILE_CELLS` cells with the halo, a bitset of 16 words), and per column of
  the tile the bitsets of its cells in the outer window's rows and in the guard window's
  rows. A step right XORs four column bitsets into the ring (whole words, a loop that
  vectorises), a row down flips four bits per column, and the ``k``-th set bit is found
  by counting the words' bits from the first. The work per pixel grows with the tile's
  area in words, not with the ring.
- **bit flips** (:func:`_sweep`, wider rings): tiles of up to :data:`TILE_CELLS` cells
  visited in serpentine order; each step to a neighbouring pixel changes the ring by two
  outer lines and two guard lines, ``2 (2o + 1) + 2 (2g + 1)`` bit flips (``o = g + t``),
  each also updating the count of set bits below a **pointer word**; the ``k``-th smallest
  rank is found by moving the pointer (popcounts) until the count below it is ``< k <=``
  the count through it (the answer moves little between neighbouring pixels), then
  picking the right set bit of that word. Work per pixel grows with the ring's side.

Both add the ranking (``O(M)`` per tile); memory is a few arrays of the tile's size.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

__all__ = ["ring_select"]

_JIT = {"cache": True, "nogil": True}

TILE_CELLS = 1 << 16  # cells of a tile with its halo (ranks, bitset and sort stay in cache)
COLUMN_TILE_CELLS = 1 << 10  # the same for the column-bitset sweep (16 words per bitset)
COLUMNS_MAX_OUTER = 16  # rings reaching at most this far take the column-bitset sweep

_MIN = np.int64(-(2**63))


@intrinsic
def _popcount(typingctx, x):
    """Number of set bits of an integer (LLVM ``ctpop``: one instruction on x86-64)."""

    def codegen(context, builder, signature, args):
        return builder.ctpop(args[0])

    return x(x), codegen


@intrinsic
def _lowest_bit(typingctx, x):
    """Index of the lowest set bit of a non-zero integer (LLVM ``cttz``)."""

    def codegen(context, builder, signature, args):
        return builder.cttz(args[0], context.get_constant(types.boolean, True))

    return x(x), codegen


@njit(**_JIT)
def _keys32(vals, n, out):
    """Order-preserving keys of float32 ``vals[:n]`` into the uint32 ``out``: compared as
    unsigned numbers they order as the floats do (``-0.0`` as ``+0.0``)."""
    bits = vals[:n].view(np.int32)
    for i in range(n):
        b = np.int64(bits[i])
        if b == -(2**31):
            b = 0
        out[i] = (b ^ ((b >> 31) & 0x7FFFFFFF)) + 2**31


@njit(**_JIT)
def _keys64(vals, n, out):
    """:func:`_keys32` for float64 ``vals`` into an int64 ``out`` (read as unsigned)."""
    bits = vals[:n].view(np.int64)
    for i in range(n):
        b = bits[i]
        if b == _MIN:
            b = 0
        out[i] = b ^ ((b >> 63) | _MIN)


@njit(**_JIT)
def _radix_argsort(keys, n, digits, order, tmp_order, tmp_keys):
    """Stable argsort of ``keys[:n]`` (unsigned order, ``digits`` bytes) into ``order[:n]``;
    ``keys`` is overwritten. LSD radix with 8-bit digits; a digit equal for every key is
    skipped."""
    counts = np.zeros((digits, 256), dtype=np.int32)
    for i in range(n):
        k = np.int64(keys[i])
        for d in range(digits):
            counts[d, (k >> (8 * d)) & 255] += 1
    for i in range(n):
        order[i] = i
    src_k, src_o, dst_k, dst_o = keys, order, tmp_keys, tmp_order
    swapped = False
    for d in range(digits):
        c = counts[d]
        if c.max() == n:
            continue
        start = 0
        for b in range(256):
            size = c[b]
            c[b] = start
            start += size
        shift = 8 * d
        for i in range(n):
            k = src_k[i]
            b = (k >> shift) & 255
            pos = c[b]
            c[b] = pos + 1
            dst_k[pos] = k
            dst_o[pos] = src_o[i]
        src_k, src_o, dst_k, dst_o = dst_k, dst_o, src_k, src_o
        swapped = not swapped
    if swapped:
        order[:n] = src_o[:n]


@njit(inline="always", **_JIT)
def _insert(rank, start, step, count, bits, wp, below):
    """Insert the ``count`` ranks ``rank[start + i * step]`` into the bitset; returns the
    new count of set bits in the words below the pointer ``wp``."""
    for i in range(count):
        r = rank[start + i * step]
        wi = r >> 6
        bits[wi] ^= np.int64(1) << (r & 63)
        below -= (np.int64(wi) - wp) >> 63  # + (wi < wp), without a branch
    return below


@njit(inline="always", **_JIT)
def _remove(rank, start, step, count, bits, wp, below):
    """Remove the ``count`` ranks ``rank[start + i * step]`` (see :func:`_insert`)."""
    for i in range(count):
        r = rank[start + i * step]
        wi = r >> 6
        bits[wi] ^= np.int64(1) << (r & 63)
        below += (np.int64(wi) - wp) >> 63  # - (wi < wp)
    return below


@njit(**_JIT)
def _sweep(rank, srt, tw, th, g, o, kk, out, y0, x0):
    """Visit the ``th x tw`` pixels of a ranked tile at ``(y0, x0)`` of its plane (``rank``
    over the tile with its halo, column-major, columns ``th + 2o`` long) in serpentine
    order, rows left to right then right to left; ``out[y0 + y, x0 + x]`` = the
    ``kk[y0 + y, x0 + x]``-th smallest ring value (0 where ``kk <= 0``). Column-major, the
    four lines a horizontal step changes are contiguous."""
    hh = th + 2 * o
    nwords = (srt.size + 63) >> 6
    bits = np.zeros(nwords, dtype=np.int64)
    wp, below = 0, 0
    side, band = 2 * o + 1, 2 * g + 1

    def at(y, x):  # flat index in the halo'd tile of the cell at output offsets (y, x)
        return (x + o) * hh + y + o

    for dx in range(-o, o + 1):  # the ring of pixel (0, 0), column by column
        if abs(dx) > g:
            below = _insert(rank, at(-o, dx), 1, side, bits, wp, below)
        else:
            below = _insert(rank, at(-o, dx), 1, o - g, bits, wp, below)
            below = _insert(rank, at(g + 1, dx), 1, o - g, bits, wp, below)
    x, step = 0, 1
    for y in range(th):
        for i in range(tw):
            if i:
                if step > 0:  # right: outer columns x-o out, x+o+1 in; guard x+g+1 in, x-g out
                    below = _remove(rank, at(y - o, x - o), 1, side, bits, wp, below)
                    below = _insert(rank, at(y - o, x + o + 1), 1, side, bits, wp, below)
                    below = _remove(rank, at(y - g, x + g + 1), 1, band, bits, wp, below)
                    below = _insert(rank, at(y - g, x - g), 1, band, bits, wp, below)
                else:  # left: the mirror image
                    below = _remove(rank, at(y - o, x + o), 1, side, bits, wp, below)
                    below = _insert(rank, at(y - o, x - o - 1), 1, side, bits, wp, below)
                    below = _remove(rank, at(y - g, x - g - 1), 1, band, bits, wp, below)
                    below = _insert(rank, at(y - g, x + g), 1, band, bits, wp, below)
                x += step
            k = kk[y0 + y, x0 + x]
            if k <= 0:
                out[y0 + y, x0 + x] = 0
                continue
            here = _popcount(bits[wp])
            while below + here < k and wp < nwords - 1:  # the pointer follows the answer
                below += here
                wp += 1
                here = _popcount(bits[wp])
            while below >= k:
                wp -= 1
                below -= _popcount(bits[wp])
            word = bits[wp]
            for _ in range(k - below - 1):
                word &= word - 1
            out[y0 + y, x0 + x] = srt[(wp << 6) + _lowest_bit(word)]
        if y + 1 < th:  # down: outer rows y-o out, y+o+1 in; guard y+g+1 in, y-g out
            below = _remove(rank, at(y - o, x - o), hh, side, bits, wp, below)
            below = _insert(rank, at(y + o + 1, x - o), hh, side, bits, wp, below)
            below = _remove(rank, at(y + g + 1, x - g), hh, band, bits, wp, below)
            below = _insert(rank, at(y - g, x - g), hh, band, bits, wp, below)
            step = -step


@njit(inline="always", **_JIT)
def _toggle(bits, at, r):
    """Flip rank ``r`` of the bitset from word ``at`` of ``bits``."""
    bits[at + (r >> 6)] ^= np.int64(1) << (r & 63)


@njit(inline="always", **_JIT)
def _kth(bits, k, n):
    """The rank of the ``k``-th smallest set bit of the first ``n`` (unsigned) words of a
    bitset (``k >= 1``, at most their count), without a data-dependent branch (a branch
    per pixel that the predictor cannot learn cost more than the counting): every word's
    bits are counted, the words wholly below the ``k``-th bit are counted with them, then
    the bit is picked within its word (:func:`_select_bit`)."""
    run, below, at = 0, 0, 0
    for wi in range(n):
        run += _popcount(bits[wi])
        under = run < k
        at += under
        below = run if under else below
    at = min(at, np.int64(n) - 1)  # in bounds even for a k past the count (never passed)
    return (at << 6) + _select_bit(bits[at], k - 1 - below)


_M1 = np.uint64(0x5555555555555555)
_M2 = np.uint64(0x3333333333333333)
_M4 = np.uint64(0x0F0F0F0F0F0F0F0F)
_ONES = np.uint64(0x0101010101010101)  # 1 in every byte
_HIGH = np.uint64(0x8080808080808080)  # the top bit of every byte
_SELECT = np.array(  # _SELECT[8 v + r]: the position of the r-th set bit of the byte v
    [
        [[i for i in range(8) if v >> i & 1][r] if r < bin(v).count("1") else 0 for r in range(8)]
        for v in range(256)
    ],
    dtype=np.int64,
).reshape(-1)


@njit(inline="always", **_JIT)
def _select_bit(word, j):
    """The position of the ``j``-th (from 0) set bit of a word with more than ``j``, without
    a branch: each byte's count of the bits up to it (one multiplication), the bytes whose
    count is at most ``j`` counted at once (the top bit of each byte of ``(count + 128) -
    (j + 1)``: no borrow crosses a byte), then a table for the bit within its byte."""
    x = np.uint64(word)
    s = x - ((x >> np.uint64(1)) & _M1)
    s = (s & _M2) + ((s >> np.uint64(2)) & _M2)
    s = (s + (s >> np.uint64(4))) & _M4
    upto = s * _ONES  # byte i: the set bits of bytes 0..i
    q = 8 - _popcount(((upto | _HIGH) - np.uint64(j + 1) * _ONES) & _HIGH)
    shift = np.uint64(8 * q)
    before = ((upto << np.uint64(8)) >> shift) & np.uint64(255)  # bits of bytes 0..q-1
    byte = (x >> shift) & np.uint64(255)
    return 8 * q + _SELECT[np.int64(byte) * 8 + min(j - np.int64(before), 7)]


@njit(inline="always", **_JIT)
def _pick(word, j, wi):
    """The rank of the ``j``-th lowest set bit of ``word``, word ``wi`` of a bitset."""
    for _ in range(j - 1):
        word &= word - 1
    return (wi << 6) + _lowest_bit(word)


@njit(**_JIT)
def _sweep_columns(rank, srt, tw, th, g, o, kk, out, y0, x0, outer, guard, ring):
    """:func:`_sweep`'s result by whole-word operations, for small tiles (a dense bitset of
    ``nw`` words). Per column of the halo'd tile, the bitsets of its rows in the outer
    window and in the guard window (``outer``, ``guard``: scratch of ``(tw + 2o) nw``
    words at least; a row down flips four bits per column). A pixel's ring is the XOR of
    its ``2o + 1`` outer and ``2g + 1`` guard column bitsets (the guard lies inside the
    outer square); a step right XORs four column bitsets into it (``ring``: ``nw`` words),
    a loop that vectorises. The ``k``-th set bit is then found by counting words from the
    first (:func:`_kth`). Indices are unsigned where the loops must vectorise (a signed
    index carries numba's negative-index check, which turns the loads into gathers)."""
    hh, wd = th + 2 * o, tw + 2 * o
    nw = (srt.size + 63) >> 6
    unw = np.uint64(nw)
    outer[: wd * nw] = 0
    guard[: wd * nw] = 0
    lo, hi = o - g, o + g  # the guard rows and columns, in the window
    for c in range(wd):
        for r in range(2 * o + 1):
            _toggle(outer, c * nw, rank[c * hh + r])
        for r in range(lo, hi + 1):
            _toggle(guard, c * nw, rank[c * hh + r])
    for y in range(th):
        if y:  # every column's windows one row down
            for c in range(wd):
                top = c * hh + y - 1
                _toggle(outer, c * nw, rank[top])
                _toggle(outer, c * nw, rank[top + 2 * o + 1])
                _toggle(guard, c * nw, rank[top + lo])
                _toggle(guard, c * nw, rank[top + hi + 1])
        for wi in range(unw):
            ring[wi] = 0
        for c in range(2 * o + 1):
            _xor_in(ring, outer, np.uint64(c * nw), unw)
        for c in range(lo, hi + 1):
            _xor_in(ring, guard, np.uint64(c * nw), unw)
        for x in range(tw):
            if x:
                a, b = np.uint64((x - 1) * nw), np.uint64((x + 2 * o) * nw)
                e, d = np.uint64((x - 1 + lo) * nw), np.uint64((x + hi) * nw)
                for wi in range(unw):
                    ring[wi] ^= (outer[a + wi] ^ outer[b + wi]) ^ (guard[e + wi] ^ guard[d + wi])
            k = kk[y0 + y, x0 + x]
            out[y0 + y, x0 + x] = srt[_kth(ring, k, unw)] if k > 0 else 0


@njit(inline="always", **_JIT)
def _xor_in(ring, bits, at, n):
    """``ring[:n] ^= bits[at : at + n]`` (unsigned indices: a loop that vectorises)."""
    for wi in range(n):
        ring[wi] ^= bits[at + wi]


@njit(**_JIT)
def _scratch(plane, side, columns):
    """The buffers of :func:`_select_plane` for halo'd tiles of ``side`` x ``side`` cells,
    allocated once per call (fresh large arrays per tile would cost page faults)."""
    span = side * side
    words = (span + 63) >> 6
    narrow = plane.itemsize == 4  # float32: 32-bit keys, four radix passes at most
    return (
        np.empty(span, dtype=plane.dtype),  # cell values
        np.empty(span if narrow else 0, dtype=np.uint32),  # keys, float32
        np.empty(span if narrow else 0, dtype=np.uint32),
        np.empty(0 if narrow else span, dtype=np.int64),  # keys, float64
        np.empty(0 if narrow else span, dtype=np.int64),
        np.empty(span, dtype=np.int32),  # order
        np.empty(span, dtype=np.int32),
        np.empty(span, dtype=np.uint32),  # ranks (unsigned: no negative-index wraparound)
        np.empty(span, dtype=plane.dtype),  # sorted values
        np.zeros(side * words if columns else 0, dtype=np.int64),  # column bitsets
        np.zeros(side * words if columns else 0, dtype=np.int64),
        np.zeros(words, dtype=np.int64),  # the ring (_sweep_columns)
    )


@njit(**_JIT)
def _select_plane(plane, kk, valid, has_valid, g, o, tile, columns, out, scratch):
    """Every tile of one ``(H, W)`` plane: rank its halo'd cells, then sweep it (by column
    bitsets where ``columns``, else by bit flips)."""
    h, w = plane.shape
    vals, keys32, tmp32, keys64, tmp64, order, tmp_order, rank, srt = scratch[:9]
    outer, guard, ring = scratch[9:]
    narrow = plane.itemsize == 4
    for y0 in range(0, h, tile):
        for x0 in range(0, w, tile):
            th, tw = min(tile, h - y0), min(tile, w - x0)
            hh, wd = th + 2 * o, tw + 2 * o
            m = hh * wd
            for j in range(wd):  # column-major (see _sweep)
                for i in range(hh):
                    y, x = y0 + i - o, x0 + j - o
                    v = np.inf
                    if 0 <= y < h and 0 <= x < w and (not has_valid or valid[y, x]):
                        v = plane[y, x]
                    vals[j * hh + i] = v
            if narrow:
                _keys32(vals, m, keys32)
                _radix_argsort(keys32, m, 4, order, tmp_order, tmp32)
            else:
                _keys64(vals, m, keys64)
                _radix_argsort(keys64, m, 8, order, tmp_order, tmp64)
            for i in range(m):
                rank[order[i]] = i
                srt[i] = vals[order[i]]
            if columns:
                _sweep_columns(rank[:m], srt[:m], tw, th, g, o, kk, out, y0, x0, outer, guard, ring)
            else:
                _sweep(rank[:m], srt[:m], tw, th, g, o, kk, out, y0, x0)


def by_columns(o: int) -> bool:
    """Whether rings reaching ``o`` cells from the pixel take the column-bitset sweep: its
    work per pixel grows with the halo'd tile's area, the bit flips' with the ring's side,
    so the flips win for wide rings."""
    return o <= COLUMNS_MAX_OUTER


def tile_side(h: int, w: int, o: int) -> int:
    """Side of the output tiles: the whole plane when it fits the sweep's budget
    (:data:`COLUMN_TILE_CELLS` for :func:`by_columns` rings, else :data:`TILE_CELLS`) with
    its halo, else the largest square that does (at least ``2o + 1`` and 16)."""
    cells = COLUMN_TILE_CELLS if by_columns(o) else TILE_CELLS
    if (h + 2 * o) * (w + 2 * o) <= cells:
        return max(h, w)
    return max(int(cells**0.5) - 2 * o, 2 * o + 1, 16)


@njit(**_JIT)
def _select_planes(planes, kk, valid, has_valid, g, o, tile, columns, out):
    """:func:`_select_plane` for every plane (``kk`` and ``valid`` may have one plane for
    all)."""
    scratch = _scratch(planes, tile + 2 * o, columns)
    for p in range(planes.shape[0]):
        kp = kk[p if kk.shape[0] > 1 else 0]
        vp = valid[p if has_valid else 0]
        _select_plane(planes[p], kp, vp, has_valid, g, o, tile, columns, out[p], scratch)


def ring_select(
    planes: np.ndarray, guard: int, train: int, kk: np.ndarray, valid: np.ndarray | None
) -> np.ndarray:
    """The ``kk``-th smallest counted ring value at every pixel of ``planes`` ``(P, H, W)``
    (float32 or float64, C-contiguous).

    ``kk``: int64 ``(P, H, W)`` or ``(1, H, W)`` (the same ranks for every plane), 1-based,
    at most the pixel's count of counted cells (``<= 0`` gives 0). ``valid``: an optional
    bool mask of counted cells, ``(P, H, W)``.
    """
    o = guard + train
    h, w = planes.shape[1:]
    out = np.empty_like(planes)
    mask = np.ones((1, 1, 1), dtype=np.bool_) if valid is None else valid
    tile = tile_side(h, w, o)
    _select_planes(planes, kk, mask, valid is not None, guard, o, tile, by_columns(o), out)
    return out
