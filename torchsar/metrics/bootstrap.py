"""Poisson bootstrap over images: replicate weights that need no state and no order.

Each resampling unit (an image, or a group of images such as the scene they were cut from)
gets, for every replicate ``r``, a weight ``w_r ~ Poisson(1)`` that is a pure function of
``(seed, unit, r)``: a 64-bit hash of the unit's key (:func:`unit_hash`) mixed with the seed
and the replicate number by SplitMix64, turned into a uniform number and then into a
Poisson(1) count by its inverse distribution function. So any split of a dataset into
batches, shards or workers, and any order, draws the same weights; every detector of a run
gets the same weights for the same units (the paired comparisons rely on it); and the
weights of a whole dataset are computed at once, vectorised, when the metrics are read
(Hanley & MacGibbon, "Creating non-parametric bootstrap samples using Poisson frequencies",
Comput. Methods Programs Biomed. 83(1), 2006, doi:10.1016/j.cmpb.2006.04.006). The intervals
built on the replicates are in :mod:`torchsar.metrics.intervals`.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence

import numpy as np

__all__ = ["interval", "poisson_weights", "unit_hash"]

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_CDF = np.cumsum([math.exp(-1.0) / math.factorial(k) for k in range(24)])
_THRESHOLDS = [np.uint64(int(c * 2.0**64)) for c in _CDF if c < 1.0]
"""``x >= T[k]`` for a uniform 64-bit ``x`` with probability ``P(Poisson(1) > k)``."""
_COMMON = 7
"""Thresholds compared on every draw; a count above 7 (probability 1e-5) takes the rest."""


def unit_hash(key: str) -> int:
    """The 64-bit hash of a resampling unit's key (its image name, or ``group:NAME``).

    Examples:
        >>> unit_hash("scene-3") == unit_hash("scene-3") != unit_hash("scene-4")
        True
    """
    return int.from_bytes(hashlib.blake2b(str(key).encode(), digest_size=8).digest(), "little")


def _mix(x: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser, in place on a uint64 array (wrapping arithmetic)."""
    x ^= x >> np.uint64(30)
    x *= np.uint64(0xBF58476D1CE4E5B9)
    x ^= x >> np.uint64(27)
    x *= np.uint64(0x94D049BB133111EB)
    x ^= x >> np.uint64(31)
    return x


def _poisson(x: np.ndarray) -> np.ndarray:
    """Poisson(1) counts (uint8) of uniform 64-bit draws ``x``."""
    w = np.zeros(x.shape, np.uint8)
    for t in _THRESHOLDS[:_COMMON]:
        w += x >= t
    rare = np.flatnonzero(w == _COMMON)
    for t in _THRESHOLDS[_COMMON:]:
        w[rare] += x[rare] >= t
    return w


def poisson_weights(
    units: Sequence[str] | np.ndarray, replicates: int, seed: int = 0
) -> np.ndarray:
    """Replicate weights ``(replicates, len(units))`` uint8, one column per unit.

    Args:
        units: the units' keys (strings) or their :func:`unit_hash` values (uint64).
        replicates: number of bootstrap replicates.
        seed: the bootstrap seed.

    Examples:
        >>> w = poisson_weights(["a", "b"], 4, seed=1)
        >>> w.shape, w.dtype.name
        ((4, 2), 'uint8')
        >>> bool((w[:, 1] == poisson_weights(["b"], 4, seed=1)[:, 0]).all())  # others don't matter
        True
    """
    if isinstance(units, np.ndarray) and units.dtype == np.uint64:
        h = units.reshape(-1)
    else:
        h = np.array([unit_hash(u) for u in units], dtype=np.uint64)
    out = np.empty((int(replicates), h.size), np.uint8)
    with np.errstate(over="ignore"):
        s = _mix(np.array([int(seed) & 0xFFFFFFFFFFFFFFFF], np.uint64) * _GOLDEN)
        rows = _mix(s + np.arange(1, int(replicates) + 1, dtype=np.uint64) * _GOLDEN)
        for r in range(int(replicates)):  # row by row: each step stays in the cache
            out[r] = _poisson(_mix(h ^ rows[r]))
    return out


def interval(values: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    """Plain percentile interval of replicate values (NaN replicates left out). Not what the
    tables report (zero width at a perfect count, too narrow at small samples): see
    :mod:`torchsar.metrics.intervals`; kept to compare against."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan"), float("nan")
    a = 100 * (1 - level) / 2
    lo, hi = np.percentile(v, [a, 100 - a])
    return float(lo), float(hi)
