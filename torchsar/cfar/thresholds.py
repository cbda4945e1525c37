"""Threshold factors that make a CFAR statistic keep its design false-alarm probability.

Each factor is a pure function of the number of training cells ``n`` and ``pfa`` (plus the
variant's own parameters), cached, so border pixels with fewer training cells (and no-data
masks) get the exact factor for their own ``n``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import lru_cache

import torch
from scipy import special
from torch import Tensor

__all__ = ["ca_factor", "factor_map", "gaussian_factor"]


@lru_cache(maxsize=4096)
def ca_factor(n: int, pfa: float, looks: float = 1.0) -> float:
    """CA-CFAR threshold factor ``alpha`` on ``I / mean_ring`` for L-look gamma clutter.

    With ``L`` looks, ``I / mean_ring`` follows an F distribution with ``(2L, 2NL)`` degrees of
    freedom, so ``alpha`` is its ``1 - pfa`` quantile, computed through the regularised
    incomplete beta inverse. For ``L = 1`` (exponential clutter) this is the closed form
    ``alpha = N (pfa^(-1/N) - 1)``.

    References:
        Finn & Johnson (1968); Gandhi & Kassam, IEEE TAES 24(4), 1988, doi:10.1109/7.7181.

    Example:
        >>> round(ca_factor(16, 1e-3), 6) == round(16 * (1e-3 ** (-1 / 16) - 1), 6)
        True
    """
    if n <= 0:
        return math.inf
    if looks == 1.0:
        return n * (pfa ** (-1.0 / n) - 1.0)
    b = float(special.betaincinv(looks, n * looks, 1.0 - pfa))
    return n * b / (1.0 - b)


@lru_cache(maxsize=64)
def gaussian_factor(pfa: float) -> float:
    """``K = Phi^-1(1 - pfa)``, the two-parameter CFAR threshold (seed eq. 1)."""
    return float(special.ndtri(1.0 - pfa))


def factor_map(count: Tensor, factor: Callable[[int], float]) -> Tensor:
    """Evaluate a scalar factor function at every distinct training-cell count.

    Args:
        count: float tensor of (integer-valued) training-cell counts.
        factor: ``factor(n) -> float`` (cache it: it is called once per distinct count).

    Returns:
        Tensor like ``count`` (float64) holding ``factor(count)``.
    """
    idx = count.round().long().clamp_min(0)
    present = torch.bincount(idx.flatten(), minlength=1).nonzero().flatten().tolist()
    table = torch.zeros(max(present, default=0) + 1, dtype=torch.float64)
    table[present] = torch.tensor([factor(n) for n in present], dtype=torch.float64)
    return table.to(count.device)[idx]
