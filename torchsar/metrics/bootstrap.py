"""Poisson bootstrap over images: fixed-size, mergeable resampling.

Each image gets, for every replicate ``r``, a weight ``w_r ~ Poisson(1)`` drawn from a
generator seeded by ``(seed, image key)`` only. Replicate states are sums of weighted
per-image contributions, so they add up across batches, shards and workers, their size does
not grow with the dataset, and any split gives the same intervals (Hanley & MacGibbon,
"Creating non-parametric bootstrap samples using Poisson frequencies", Comput. Methods
Programs Biomed. 83(1), 2006, doi:10.1016/j.cmpb.2006.04.006). The intervals built on the
replicates are in :mod:`torchsar.metrics.intervals`.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from functools import lru_cache

import numpy as np

__all__ = ["interval", "poisson_weights"]


def poisson_weights(keys: Sequence[str], replicates: int, seed: int = 0) -> np.ndarray:
    """Replicate weights ``(replicates, len(keys))`` int32, one column per image key.

    Example:
        >>> w = poisson_weights(["a", "b"], 4, seed=1)
        >>> w.shape
        (4, 2)
        >>> bool((w[:, 1] == poisson_weights(["b"], 4, seed=1)[:, 0]).all())  # others don't matter
        True
    """
    out = np.empty((replicates, len(keys)), dtype=np.int32)
    for j, key in enumerate(keys):
        out[:, j] = _weights(key, int(replicates), int(seed))
    return out


@lru_cache(maxsize=4096)  # every detector of a run asks for the same images' weights
def _weights(key: str, replicates: int, seed: int) -> np.ndarray:
    """One image's replicate weights (read-only)."""
    digest = hashlib.blake2b(key.encode(), digest_size=16).digest()
    words = np.frombuffer(digest, dtype=np.uint32)
    w = np.random.default_rng([seed, *words.tolist()]).poisson(1.0, replicates)
    w.flags.writeable = False
    return w


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
