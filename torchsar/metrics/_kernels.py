"""numba kernels of the pixel ROC: the class-by-bucket histogram of a batch in one pass, with
the counts of :meth:`~torchsar.metrics.RocAccumulator.update`'s tensor code, exactly, and
without its intermediate tensors.

A value's bucket is the number of grid values strictly below it (``torch.bucketize``,
comparing in the value's own dtype); the class is 0 for a target pixel, 1 for clutter and 2
for an ignored one.

- float32 values (any sorted grid): the top 16 bits of a float32 (sign, exponent and 7
  mantissa bits) select a range of values; :func:`float32_starts` gives for every such range
  the bucket of its lowest value, and the bucket of a value is found by stepping up from
  there past the grid values below it (none or one on a log grid with steps above 1 %).
- float64 values on the symmetric log grid: the bucket follows from ``log10 |x|``; a value
  within 1e-2 grid steps of a grid value takes the exact binary search instead, as
  :class:`~torchsar.metrics.log_bins.LogGrid` does.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["float32_roc_pass", "float32_starts", "log_grid_histogram"]

_JIT = {"cache": True, "nogil": True}


def float32_starts(grid: np.ndarray) -> np.ndarray:
    """``(65536,)`` int32: for each value of a float32's top 16 bits, the number of ``grid``
    values (float32, ascending) strictly below the lowest non-NaN float32 with those bits.

    Within one such range the values are monotonic in their bits, so the lowest is at one
    end; a range of NaNs (exponent all ones) holds only an infinity at its first end.
    """
    keys = np.arange(1 << 16, dtype=np.uint32) << np.uint32(16)
    ends = [keys.view(np.float32), (keys | np.uint32(0xFFFF)).view(np.float32)]
    starts = [np.where(np.isnan(e), grid.size, np.searchsorted(grid, e, side="left")) for e in ends]
    return np.minimum(*starts).astype(np.int32)


@njit(**_JIT)
def _search(grid, x):
    """Number of grid values strictly below ``x`` (``grid`` ascending)."""
    lo, hi = 0, grid.size
    while lo < hi:
        mid = (lo + hi) // 2
        if grid[mid] < x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(**_JIT)
def _log_bucket(x, grid, m, low, ppd, sure):
    if x == 0.0:
        return m
    ax = abs(x)
    if ax == math.inf:
        return 2 * m + 1 if x > 0 else 0
    a = (math.log10(ax) - low) * ppd
    if abs(a - np.rint(a)) < sure:
        return _search(grid, x)
    k = min(max(math.ceil(a), 0), m)
    return m + k + 1 if x > 0 else m - k


@njit(**_JIT)
def log_grid_histogram(values, target, ignore, has_ignore, grid, m, low, ppd, sure):
    """``(3, grid.size + 1)`` int64 counts of (class, bucket) over flat float64 ``values`` on
    the symmetric log grid with ``m`` values each side of 0 from ``10^low``, ``ppd`` per
    decade."""
    hist = np.zeros((3, grid.size + 1), np.int64)
    for i in range(values.size):
        cls = 0 if target[i] else 1
        if has_ignore and ignore[i]:
            cls = 2
        hist[cls, _log_bucket(values[i], grid, m, low, ppd, sure)] += 1
    return hist


@njit(**_JIT)
def float32_roc_pass(values, target, ignore, has_ignore, detected, grid, starts):
    """``(3, grid.size + 1)`` int64 counts of (class, bucket) over flat float32 ``values``
    (``starts``: :func:`float32_starts` of ``grid``), in the same pass the pixel counts of
    the detection mask ``detected`` (``[tp, detected, targets, counted]`` over the pixels not
    ignored, as :func:`~torchsar.metrics.pixel_counts` counts them), and whether a value is
    NaN (then nothing is to be used)."""
    n = grid.size
    hist = np.zeros((3, n + 1), np.int64)
    counts = np.zeros(4, np.int64)
    bits = values.view(np.uint32)
    nan = False
    for i in range(values.size):
        x = values[i]
        if x != x:
            nan = True
            break
        b = starts[bits[i] >> 16]
        while b < n and grid[b] < x:
            b += 1
        if has_ignore and ignore[i]:
            hist[2, b] += 1
            continue
        t, d = target[i], detected[i]
        hist[0 if t else 1, b] += 1
        counts[0] += t and d
        counts[1] += d
        counts[2] += t
        counts[3] += 1
    return hist, counts, nan
