"""numba kernels of the object matching: COCO's greedy assignment of every problem from its
candidate pairs (:func:`torchsar.metrics.greedy.assign_pairs`) and the pixel intersections
of two sets of pixel lists (:func:`torchsar.metrics.assign.join_pixels`). The same results
as their numpy code, which stays as the fallback and as the reference the tests compare
against, in one compiled call each instead of a few dozen numpy calls: a batch of chips
holds a few objects per problem, so those calls' overhead, not their work, was the cost.

Import this module only when :func:`torchsar._jit.enabled` (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["ascending", "greedy_pairs", "join_pixels"]

_JIT = {"cache": True, "nogil": True, "boundscheck": False}


@njit(**_JIT)
def greedy_pairs(pd, pg, pq, g_ignore, g_crowd, thr, out):
    """The greedy matching of :func:`torchsar.metrics.greedy.assign_pairs` into ``out``
    ``(D, A, T)`` (filled with -1): ``pd``, ``pg``, ``pq`` the candidate pairs sorted by
    detection, then quality, then instance (ascending), the detections of a problem
    numbered in visiting order. Each detection, in turn, takes per area range and threshold
    the last free pair of its own at or above the threshold whose instance counts (not
    ignored in that range), else the last such pair of an ignored instance (pycocotools'
    choice: highest quality, ties the later instance, counted before ignored); a taken
    instance is no longer free unless it is a crowd one."""
    n_pairs = pd.shape[0]
    n_ranges, n_thr = g_ignore.shape[1], thr.shape[0]
    free = np.ones((g_ignore.shape[0], n_ranges, n_thr), np.bool_)
    first = 0
    while first < n_pairs:
        d = pd[first]
        end = first
        while end < n_pairs and pd[end] == d:
            end += 1
        for a in range(n_ranges):
            for t in range(n_thr):
                took, fallback = -1, -1
                for k in range(end - 1, first - 1, -1):  # highest quality first
                    if pq[k] < thr[t]:
                        break  # the rest are lower still
                    g = pg[k]
                    if not free[g, a, t]:
                        continue
                    if not g_ignore[g, a]:
                        took = g
                        break
                    if fallback < 0:
                        fallback = g
                if took < 0:
                    took = fallback
                if took >= 0:
                    out[d, a, t] = took
                    if not g_crowd[took]:
                        free[took, a, t] = False
        first = end


_DENSE_PAIRS = 1 << 20  # pair counts kept in a dense (a, b) table up to this many cells


@njit(**_JIT)
def ascending(x):
    """Whether ``x`` is in ascending order (ties allowed)."""
    for k in range(1, x.shape[0]):  # noqa: SIM110 (numba compiles no generator)
        if x[k] < x[k - 1]:
            return False
    return True


@njit(**_JIT)
def join_pixels(a_owner, a_pix, b_owner, b_pix):
    """``(a, b, shared)`` of :func:`torchsar.metrics.assign.join_pixels` (non-empty lists
    of ``int64``, the ``b`` pixels in ascending order: :func:`ascending`): every pair of an
    ``a`` list and a ``b`` list that share pixels, ascending by ``(a, b)``, with the count
    of pixels they share (the ``b`` lists may overlap each other). Each ``a`` pixel is
    found among the ``b`` pixels (:func:`_ranges`): memory and time follow the pixels, not
    the image (a table over the image's pixels would cost more to clear than all of
    this)."""
    n_b = b_owner.max() + 1
    first, last = _ranges(a_pix, b_pix)
    keys = np.empty(int((last - first).sum()), np.int64)
    m = 0
    for i in range(a_pix.shape[0]):
        for k in range(first[i], last[i]):
            keys[m] = a_owner[i] * (n_b + 1) + b_owner[k]
            m += 1
    return _pair_counts(keys, a_owner.max() + 1, n_b)


@njit(**_JIT)
def _ranges(a_pix, b_pix):
    """Where each ``a`` pixel's equals start and end among the ascending ``b`` pixels: one
    walk through both where the ``a`` pixels ascend too (pixel lists usually do), else a
    binary search per ``a`` pixel."""
    if not ascending(a_pix):
        return np.searchsorted(b_pix, a_pix, side="left"), np.searchsorted(
            b_pix, a_pix, side="right"
        )
    n_a, n_b = a_pix.shape[0], b_pix.shape[0]
    first, last = np.empty(n_a, np.int64), np.empty(n_a, np.int64)
    k = 0
    for i in range(n_a):
        while k < n_b and b_pix[k] < a_pix[i]:
            k += 1
        e = k
        while e < n_b and b_pix[e] == a_pix[i]:
            e += 1
        first[i], last[i] = k, e
    return first, last


@njit(**_JIT)
def _pair_counts(keys, n_a, n_b):
    """The distinct pairs of ``keys`` (``a (n_b + 1) + b``) ascending, with how often each
    occurs: in a dense ``(a, b)`` table when it is small, else by sorting."""
    if n_a * (n_b + 1) <= _DENSE_PAIRS:
        table = np.zeros(n_a * (n_b + 1), np.int64)
        for k in range(keys.shape[0]):
            table[keys[k]] += 1
        pairs = np.flatnonzero(table)
        counts = table[pairs]
    else:
        keys = np.sort(keys)
        starts = np.flatnonzero(
            np.concatenate((np.ones(min(keys.shape[0], 1), np.bool_), keys[1:] != keys[:-1]))
        )
        pairs = keys[starts]
        counts = np.diff(np.append(starts, keys.shape[0]))
    return pairs // (n_b + 1), pairs % (n_b + 1), counts.astype(np.int64)
