"""numba kernels of the pixel ROC: the per-key target and clutter counts of a batch, and the
pixel counts of a detection mask, in one compiled call; the same counts as
:meth:`~torchsar.metrics.RocAccumulator.update`'s tensor code, without its intermediate
tensors.

A value's key (:func:`torchsar.metrics.roc.pixel_keys`) comes from the bits of its float64
value (a float32 is converted exactly). Given the smallest and largest finite value of the
batch (numpy's ``min`` and ``max``, :func:`finite_range` when one of them is infinite),
:func:`roc_pass` counts the pixels in a dense table over the keys of that range (a range
that spans zero, tens of thousands of keys, over the keys of the exponents present), with
one row for ``+inf`` and one for ``-inf``; the detection counts take a second loop, which
vectorises.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

__all__ = ["finite_range", "roc_pass"]

_JIT = {"cache": True, "nogil": True}

MANTISSA_BITS = 5
"""The mantissa bits a key keeps, as :data:`torchsar.metrics.roc.MANTISSA_BITS` (defined
here, not imported from there: numba's cache freezes a global at compile time and is only
invalidated when this file changes)."""
_LOW63 = (1 << 63) - 1  # every bit but the sign
_CHUNK = 4096  # pixels whose slots are formed before they are counted
_SHIFT = 64 - 12 - MANTISSA_BITS  # the key: the sign, 11 exponent bits, MANTISSA_BITS more


@intrinsic
def _bits(typingctx, x):
    """The IEEE bits of a float64 as an int64 (a bit cast)."""
    if x != types.float64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.int64))

    return types.int64(types.float64), codegen


@njit(**_JIT)
def _key(x):
    """The key of a non-NaN value (any float type: converted to float64 exactly)."""
    b = _bits(np.float64(x) + 0.0)  # + 0.0: -0.0 becomes +0.0
    return (b ^ ((b >> 63) & _LOW63)) >> _SHIFT


@njit(**_JIT)
def finite_range(values):
    """The smallest and largest finite value (``inf, -inf`` when there is none; values free
    of NaN)."""
    lo, hi = math.inf, -math.inf
    for i in range(values.size):
        x = values[i]
        if abs(x) != math.inf:
            lo = min(lo, x)
            hi = max(hi, x)
    return lo, hi


_DENSE_ROWS = 1 << 13
"""Rows of a batch's key range up to which its table is dense; beyond (a range that spans
zero, whose every exponent from the smallest normal up then gets 32 rows on each side of
it: 65,693 rows for a statistic from -1.4 to 94), only the exponents present get rows."""


@njit(**_JIT)
def _row_map(values, kmin, n):
    """For a key range ``kmin .. kmin + n - 1``: each group of 32 keys' (one exponent's)
    first row, or -1 where no finite value of ``values`` falls (a pass over the values),
    the key of every row, and the count of rows."""
    g0 = kmin >> 5
    groups = ((kmin + n - 1) >> 5) - g0 + 1
    first = np.full(groups, -1, np.int64)
    for i in range(values.size):
        x = values[i]
        if abs(x) != math.inf:
            first[(_key(x) >> 5) - g0] = 0
    rows = 0
    for g in range(groups):
        if first[g] == 0:
            first[g] = rows
            rows += 32
    row_keys = np.empty(rows, np.int64)
    for g in range(groups):
        if first[g] >= 0:
            for r in range(32):
                row_keys[first[g] + r] = ((g0 + g) << 5) + r
    return first, row_keys, rows


@njit(**_JIT)
def roc_pass(values, lo, hi, target, ignore, has_ignore, detected, has_detected):
    """Per-key counts of a flat NaN-free float32 or float64 batch whose finite values lie in
    ``[lo, hi]`` (``lo > hi``: none is finite).

    Returns ``(row_keys, table, tp, detected)``: ``table`` ``(n + 2, 2)`` int64 holds the
    target (column 0) and clutter (column 1) pixels not ignored of key ``row_keys[j]`` in
    row ``j < n``, of ``+inf`` in row ``n`` and of ``-inf`` in row ``n + 1``; with
    ``has_detected``, the detected target pixels and the detected pixels not ignored (else
    0, 0). The rows are every key of the range (up to :data:`_DENSE_ROWS`), else only the
    keys of the exponents present (:func:`_row_map`).
    """
    kmin, n = 0, 0
    if lo <= hi:
        kmin = _key(lo)
        n = _key(hi) - kmin + 1
    compact = n > _DENSE_ROWS
    if compact:
        first, row_keys, n = _row_map(values, kmin, n)
    else:
        first, row_keys = np.zeros(0, np.int64), np.arange(kmin, kmin + n)
    g0 = kmin >> 5
    table = np.zeros(2 * n + 5, np.int64)  # the last slot: ignored pixels, dropped below
    slot = np.empty(min(values.size, _CHUNK), np.int64)
    t8, i8 = target.view(np.uint8), ignore.view(np.uint8)
    for s0 in range(0, values.size, _CHUNK):  # each pixel's slot in a loop that vectorises,
        m = min(_CHUNK, values.size - s0)  # then the counts (a scatter: one at a time)
        v, tg, ig = values[s0 : s0 + m], t8[s0 : s0 + m], i8[s0 : s0 + m]
        if compact:
            for i in range(m):
                x = v[i]
                row = n if x == math.inf else n + 1
                if abs(x) != math.inf:
                    k = _key(x)
                    row = first[(k >> 5) - g0] + (k & 31)
                slot[i] = 2 * n + 4 if has_ignore and ig[i] else 2 * row + 1 - np.int64(tg[i])
        else:
            for i in range(m):
                row = min(_key(v[i]) - kmin, n)  # only +inf is above the last finite key
                row = n + 1 if row < 0 else row  # only -inf is below the first
                k = 2 * row + 1 - np.int64(tg[i])
                slot[i] = 2 * n + 4 if has_ignore and ig[i] else k
        for i in range(m):
            table[slot[i]] += 1
    table = table[: 2 * n + 4]
    tp, nd = _detected(target, ignore, has_ignore, detected) if has_detected else (0, 0)
    return row_keys, table.reshape(n + 2, 2), tp, nd


@njit(**_JIT)
def _detected(target, ignore, has_ignore, detected):
    """Detected target pixels and detected pixels, not ignored (a loop that vectorises)."""
    t8, d8, i8 = target.view(np.uint8), detected.view(np.uint8), ignore.view(np.uint8)
    tp, nd = 0, 0
    if has_ignore:
        for i in range(t8.size):
            d = d8[i] & (1 - i8[i])
            nd += d
            tp += d & t8[i]
    else:
        for i in range(t8.size):
            nd += d8[i]
            tp += d8[i] & t8[i]
    return tp, nd
