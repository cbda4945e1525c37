"""numba primitives of the window sums of the one-sweep kernels: sums of ``L`` consecutive
terms as the power-of-two blocks of ``L``'s binary digits, from block sums of ``2^k``
terms kept per level (down the rows in ring buffers as each row arrives, along a row in
padded arrays). Every sum is of non-negative terms (or the terms as given) in an order
fixed by the pixel's position alone: no running sum and no integral image, so nothing
cancels and no value depends on the batch, tile or strip.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = [
    "FINITE_MAX",
    "FMA",
    "JIT",
    "add_blocks",
    "axis_count",
    "block_list",
    "block_sums",
    "kept_row",
    "level_up",
    "levels_for",
    "pair_rings",
    "pair_row",
    "ring_levels",
    "ring_row",
    "take_row",
    "valid_row",
]

# The numba options of every kernel of the one-sweep filters. fastmath is always set: numba
# compiles a helper that sets none with the fastmath flags of its first caller, so its
# results would depend on which kernel happened to compile it.
JIT = {
    "cache": True,
    "nogil": True,
    "error_model": "numpy",
    "boundscheck": False,
    "fastmath": False,
}
FMA = {**JIT, "fastmath": {"contract"}}  # a * b + c as one fused multiply-add

FINITE_MAX = np.finfo(np.float64).max


@njit(**JIT)
def axis_count(i, n, lo, hi):
    """How many of the offsets ``lo..hi`` from ``i`` land in ``[0, n)``."""
    a = max(i + lo, 0)
    b = min(i + hi, n - 1)
    return max(b - a + 1, 0)


@njit(**JIT)
def levels_for(length):
    """How many block-sum levels a sum of ``length`` terms needs (``2^k <= length``)."""
    k = 0
    while (2 << k) <= length:
        k += 1
    return k + 1


@njit(**JIT, inline="always")
def level_up(lo, out, step, n):
    """``out[j] = lo[j] + lo[j + step]`` for ``j < n``: one level of block sums."""
    a, b, o = lo[:n], lo[step : step + n], out[:n]  # slices: j alone indexes (vectorises)
    for j in range(n):
        o[j] = a[j] + b[j]


@njit(**JIT, inline="always")
def ring_levels(ring, q, size, depth, w):
    """Every block sum ending at row ``q`` of the ring ``ring[k, slot]`` (row ``r``'s sum
    of rows ``r .. r + 2^k - 1`` in slot ``r % size``), from the level below; level 0 of
    row ``q`` must be in."""
    for k in range(1, depth):
        r = q - (1 << k) + 1
        half = 1 << (k - 1)
        a, b, dst = ring[k - 1, r % size], ring[k - 1, (r + half) % size], ring[k, r % size]
        for j in range(w):
            dst[j] = a[j] + b[j]


@njit(**JIT, inline="always")
def add_blocks(a, b, n, out, first, pair):
    """``out[:n] (+)= a (+ b)``: assign when ``first``, add otherwise; ``b`` only when
    ``pair`` (two terms in one pass)."""
    o = out[:n]
    if pair:
        if first:
            for j in range(n):
                o[j] = a[j] + b[j]
        else:
            for j in range(n):
                o[j] += a[j] + b[j]
    elif first:
        for j in range(n):
            o[j] = a[j]
    else:
        for j in range(n):
            o[j] += a[j]


@njit(**JIT, inline="always")
def block_sums(src, size, length, starts, n, out, accumulate):
    """``out[j] (+)=`` the sums of ``length`` terms from each of ``starts`` (a tuple), from
    block sums of ``2^k`` terms: the blocks of ``length``'s set bits, largest first, start
    after start, two blocks per pass (a fixed association whatever ``j``). ``size == 0``:
    ``src[k, p + j]`` is the block of level ``k`` at ``p + j`` (along a row); else ``src``
    is a ring of ``size`` rows per level, the block starting at row ``p`` in row ``k size
    + p % size``."""
    first = not accumulate
    held, held_off = -1, 0
    for start in starts:
        pos = start
        k = levels_for(length) - 1
        while k >= 0:
            if (length >> k) & 1:
                row, off = (k * size + pos % size, 0) if size else (k, pos)
                if held < 0:
                    held, held_off = row, off
                else:
                    a = src[held, held_off : held_off + n]
                    add_blocks(a, src[row, off : off + n], n, out, first, True)
                    first, held = False, -1
                pos += 1 << k
            k -= 1
    if held >= 0:
        a = src[held, held_off : held_off + n]
        add_blocks(a, a, n, out, first, False)
    elif first:
        for j in range(n):
            out[j] = 0.0


@njit(**JIT)
def block_list(length, starts, row0, out, n):
    """The blocks :func:`block_sums` takes along a row, in its order: for each of ``starts``
    the blocks of ``length``'s set bits, largest first, as ``(row0 + k, position)`` (level
    ``k``) into ``out[n:]``; returns the new ``n``."""
    for start in starts:
        pos = start
        k = levels_for(length) - 1
        while k >= 0:
            if (length >> k) & 1:
                out[n, 0], out[n, 1] = row0 + k, pos
                n += 1
                pos += 1 << k
            k -= 1
    return n


@njit(**JIT, inline="always")
def take_row(cache, q, row, present):
    """Row ``q`` (``row``, or zeros where not ``present``) into the ring, in float64; how
    many of its values are not a finite number ``>= 0`` (the kernels' input check, made as
    the values are read)."""
    dst = cache[q % cache.shape[0]]
    bad = 0
    if present:
        for j in range(dst.shape[0]):
            v = np.float64(row[j])
            dst[j] = v
            bad += not (v >= 0.0 and v <= FINITE_MAX)  # NaN fails both
    else:
        dst[:] = 0.0
    return bad


@njit(**JIT, inline="always")
def ring_row(rows, q, size, depth, src, present, w):
    """Row ``q`` of an image (``src``, or zeros where not ``present``) into the block-sum
    ring buffers ``rows[k, slot]`` (row ``r``'s sums of rows ``r .. r + 2^k - 1`` in slot
    ``r % size``), every level ending at ``q`` updated. Returns how many of its values are
    not a finite number ``>= 0`` (the input check, made as the values are read)."""
    bad = take_row(rows[0], q, src, present)
    ring_levels(rows, q, size, depth, w)
    return bad


@njit(**JIT)
def pair_rings(depth, size, w):
    """Two rings of row blocks ``(depth, size, w)`` (level ``k``, row ``r`` in slot ``r %
    size``) and their flat views ``(depth size, w)``, as :func:`block_sums` reads them."""
    rows1, rows2 = np.zeros((depth, size, w)), np.zeros((depth, size, w))
    return rows1, rows2, rows1.reshape(depth * size, w), rows2.reshape(depth * size, w)


@njit(**JIT, inline="always")
def _take_pair(ring1, ring2, q, row, present):
    """Row ``q`` into level 0 of the two rings (zeros where not ``present``): the values and
    their squares. Returns how many values of ``row`` are not a finite number ``>= 0``."""
    size = ring1.shape[0]
    d1, d2 = ring1[q % size], ring2[q % size]
    bad = 0
    if present:
        for j in range(d1.shape[0]):
            v = np.float64(row[j])
            bad += not (v >= 0.0 and v <= FINITE_MAX)  # NaN fails both
            d1[j] = v
            d2[j] = v * v
    else:
        d1[:] = 0.0
        d2[:] = 0.0
    return bad


@njit(**JIT, inline="always")
def pair_row(rows1, rows2, q, depth, row, present):
    """Row ``q`` into the two rings of row blocks (:func:`_take_pair`), every level ending
    at ``q`` updated; the count of bad values read."""
    size, w = rows1.shape[1], rows1.shape[2]
    bad = _take_pair(rows1[0], rows2[0], q, row, present)
    ring_levels(rows1, q, size, depth, w)
    ring_levels(rows2, q, size, depth, w)
    return bad


@njit(**JIT, inline="always")
def kept_row(rows1, rows2, q, depth, row, present, limit, vrow, has_valid):
    """Row ``q`` into the two rings of row blocks (zeros where not ``present``): the values
    *kept*, at or below ``limit`` and (``has_valid``) valid (``vrow``: the row's flags),
    0 elsewhere, and their count (1 or 0 per cell), every level ending at ``q`` updated.
    Returns how many values of ``row``, kept or not, are not a finite number ``>= 0``."""
    size, w = rows1.shape[1], rows1.shape[2]
    d1, d2 = rows1[0, q % size], rows2[0, q % size]
    bad = 0
    if present and has_valid:
        for j in range(w):
            v = np.float64(row[j])
            bad += not (v >= 0.0 and v <= FINITE_MAX)  # NaN fails both
            kept = (v <= limit) & (vrow[j] != 0)  # no branch: vectorises
            d1[j] = v if kept else 0.0
            d2[j] = 1.0 if kept else 0.0
    elif present:
        for j in range(w):
            v = np.float64(row[j])
            bad += not (v >= 0.0 and v <= FINITE_MAX)
            kept = v <= limit
            d1[j] = v if kept else 0.0
            d2[j] = 1.0 if kept else 0.0
    else:
        d1[:] = 0.0
        d2[:] = 0.0
    ring_levels(rows1, q, size, depth, w)
    ring_levels(rows2, q, size, depth, w)
    return bad


@njit(**JIT, inline="always")
def valid_row(rows1, rows2, rows3, q, depth, row, valid, present):
    """Row ``q`` into three rings of row blocks (zeros where not ``present``): the values
    of its valid cells, their squares, and the valid cells' count (1 or 0 per cell), every
    level ending at ``q`` updated. Returns how many values of ``row``, valid or not, are
    not a finite number ``>= 0`` (the whole image is checked, as everywhere)."""
    size, w = rows1.shape[1], rows1.shape[2]
    d1, d2, d3 = rows1[0, q % size], rows2[0, q % size], rows3[0, q % size]
    bad = 0
    if present:
        for j in range(w):
            v = np.float64(row[j])
            bad += not (v >= 0.0 and v <= FINITE_MAX)  # NaN fails both
            ok = valid[j] != 0
            d1[j] = v if ok else 0.0
            d2[j] = v * v if ok else 0.0
            d3[j] = 1.0 if ok else 0.0
    else:
        d1[:] = 0.0
        d2[:] = 0.0
        d3[:] = 0.0
    ring_levels(rows1, q, size, depth, w)
    ring_levels(rows2, q, size, depth, w)
    ring_levels(rows3, q, size, depth, w)
    return bad
