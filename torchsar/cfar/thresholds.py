"""Threshold factors that make a CFAR statistic keep its design false-alarm probability.

Each factor is a pure function of the number of training cells ``n`` and ``pfa`` (plus the
variant's own parameters), cached, so border pixels with fewer training cells (and no-data
masks) get the exact factor for their own ``n``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import lru_cache

import numpy as np
import torch
from scipy import optimize, special
from torch import Tensor

from torchsar.errors import OptionError

__all__ = [
    "block_factor",
    "ca_factor",
    "factor_map",
    "gaussian_factor",
    "keyed_factor_map",
    "os_factor",
    "os_rank",
    "student_factor",
]


@lru_cache(maxsize=4096)
def ca_factor(n: int, pfa: float, looks: float = 1.0) -> float:
    """CA-CFAR threshold factor ``alpha`` on ``I / mean_ring`` for L-look gamma clutter.

    With ``L`` looks, ``I / mean_ring`` follows an F distribution with ``(2L, 2NL)`` degrees of
    freedom, so ``alpha`` is its ``1 - pfa`` quantile, computed through the regularised
    incomplete beta inverse on the complementary side (``1 - B = I^-1(NL, L; pfa)``, so tiny
    ``pfa`` keeps full precision). For ``L = 1`` (exponential clutter) this is the closed
    form ``alpha = N (pfa^(-1/N) - 1)``.

    Raises:
        OptionError: ``looks`` so small that the quantile overflows (no finite threshold).

    References:
        Finn & Johnson (1968); Gandhi & Kassam, IEEE TAES 24(4), 1988, doi:10.1109/7.7181.

    Examples:
        >>> round(ca_factor(16, 1e-3), 6) == round(16 * (1e-3 ** (-1 / 16) - 1), 6)
        True
    """
    if n <= 0:
        return math.inf
    if looks == 1.0:
        return n * (pfa ** (-1.0 / n) - 1.0)
    c = float(special.betaincinv(n * looks, looks, pfa))  # 1 - the beta quantile
    alpha = n * (1.0 - c) / c if c > 0 else math.inf
    if not math.isfinite(alpha):
        raise OptionError(
            f"looks={looks:g} gives no finite threshold at pfa={pfa:g} with {n} training "
            f"cells: the clutter law is too heavy-tailed; use a larger looks"
        )
    return alpha


@lru_cache(maxsize=64)
def gaussian_factor(pfa: float) -> float:
    """``K = Phi^-1(1 - pfa) = -Phi^-1(pfa)``, the two-parameter CFAR threshold (seed eq. 1),
    computed on the lower tail so that any ``pfa`` in ``(0, 1)`` gives a finite ``K``.

    Examples:
        >>> round(gaussian_factor(1e-20), 4)
        9.2623
    """
    return float(-special.ndtri(pfa))


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


def os_rank(n: int, n_full: int, rank: int) -> int:
    """The rank used with ``n`` training cells when the interior rank is ``rank`` of ``n_full``:
    ``round(rank * n / n_full)`` clipped to ``[1, n]`` (equal to ``rank`` when ``n == n_full``)."""
    if n <= 0:
        return 0
    return min(n, max(1, round(rank * n / n_full)))


@lru_cache(maxsize=4096)
def os_factor(n: int, rank: int, pfa: float) -> float:
    """OS-CFAR factor ``alpha`` on ``I / x_(rank)`` for exponential clutter (Rohling 1983).

    Solves ``pfa = prod_{i=0}^{rank-1} (n - i) / (n - i + alpha)`` for ``alpha`` by bisection
    (the product falls monotonically in ``alpha``).

    References:
        Rohling, H., IEEE TAES 19(4), 608-621, 1983, doi:10.1109/TAES.1983.309350.

    Examples:
        >>> a = os_factor(16, 12, 1e-3)
        >>> p = 1.0
        >>> for i in range(12):
        ...     p *= (16 - i) / (16 - i + a)
        >>> abs(p - 1e-3) < 1e-12
        True
    """
    if n <= 0 or rank <= 0:
        return math.inf
    i = np.arange(rank, dtype=np.float64)

    def log_pfa(a: float) -> float:
        return float(np.sum(np.log(n - i) - np.log(n - i + a))) - math.log(pfa)

    hi = 1.0
    while log_pfa(hi) > 0:
        hi *= 2.0
        if hi > 1e300:  # alpha(pfa) beyond what a float64 threshold can hold
            raise OptionError(
                f"pfa={pfa!r} is too small for OS-CFAR with rank {rank} of {n} cells: its "
                "threshold factor exceeds the float64 range; use a larger pfa or rank"
            )
    return float(optimize.bisect(log_pfa, 0.0, hi, xtol=1e-14 * hi, rtol=1e-15, maxiter=400))


_GRID_FLOOR = 1e-12  # smallest block mean on the integration grid


def _log_grid(sizes: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Log-spaced nodes and trapezoid weights (in ``dz``) covering the block-mean laws."""
    return _grid_for(min(s for s in sizes if s > 0))


@lru_cache(maxsize=256)
def _grid_for(m: int) -> tuple[np.ndarray, np.ndarray]:
    """The grid of :func:`_log_grid` for blocks of at least ``m`` cells (read-only)."""
    lo, hi = _GRID_FLOOR, 12.0 + 40.0 / math.sqrt(m)
    u = np.linspace(math.log(lo), math.log(hi), 6001)
    z = np.exp(u)
    w = np.full_like(z, u[1] - u[0]) * z
    w[0] *= 0.5
    w[-1] *= 0.5
    z.flags.writeable = w.flags.writeable = False
    return z, w


@lru_cache(maxsize=512)
def _block_law(m: int, smallest: int) -> tuple[np.ndarray, np.ndarray]:
    """CDF and density of a block mean ``S / m``, ``S ~ Gamma(m, 1)``, at the nodes of the
    grid for blocks of at least ``smallest`` cells (shared by every key with that smallest
    block: a no-data mask gives thousands of keys over a few dozen block sizes)."""
    z, _ = _grid_for(smallest)
    cdf = special.gammainc(m, m * z)
    pdf = np.exp(math.log(m) + special.xlogy(m - 1, m * z) - m * z - special.gammaln(m))
    return cdf, pdf


def _block_density(sizes: tuple[int, ...], reduce: str) -> tuple[np.ndarray, np.ndarray]:
    """Nodes ``z``, weights times the density of ``max`` / ``min`` of independent block means
    ``S_j / m_j``, ``S_j ~ Gamma(m_j, 1)`` (unit-mean exponential cells)."""
    ms = [m for m in sizes if m > 0]
    z, w = _grid_for(min(ms))
    laws = [_block_law(m, min(ms)) for m in ms]
    cdf = [c if reduce == "max" else 1.0 - c for c, _ in laws]
    dens = np.zeros_like(z)
    for j, (_, pdf) in enumerate(laws):
        others = np.ones_like(z)
        for i in range(len(ms)):
            if i != j:
                others *= cdf[i]
        dens += pdf * others
    return z, w * dens


@lru_cache(maxsize=8192)
def block_factor(sizes: tuple[int, ...], pfa: float, reduce: str) -> float:
    """GO / SO factor ``alpha`` on ``I / max_j(mean_j)`` (``reduce="max"``) or
    ``I / min_j(mean_j)`` (``"min"``) for exponential clutter, exact for any block sizes.

    ``pfa(alpha) = E[exp(-alpha Z)]`` with ``Z`` the max / min of the independent block means
    (``S_j / m_j``, ``S_j ~ Gamma(m_j, 1)``); the expectation is integrated numerically on a
    fine logarithmic grid (relative error far below 1e-6) and solved for ``alpha`` by Brent's
    method. Empty blocks (``m_j = 0``) are left out; a single block gives the CA factor.

    Raises:
        OptionError: ``pfa`` so small that the integration grid cannot resolve its factor.

    References:
        Hansen & Sawyers, IEEE TAES 16(5), 1980 (GO); Trunk, IEEE TAES 14(5), 1978 (SO);
        Gandhi & Kassam, IEEE TAES 24(4), 1988, doi:10.1109/7.7181.

    Examples:
        >>> abs(block_factor((16,), 1e-3, "max") - ca_factor(16, 1e-3)) < 1e-6
        True
    """
    if sum(sizes) <= 0:
        return math.inf
    z, wd = _block_density(sizes, reduce)
    keep = wd > 0
    z, log_w = z[keep], np.log(wd[keep])

    def log_pfa(a: float) -> float:  # log E[exp(-a Z)], in logs so that tiny pfa stay finite
        v = log_w - a * z
        top = float(v.max())
        return top + math.log(float(np.exp(v - top).sum())) - math.log(pfa)

    hi = 1.0
    while log_pfa(hi) > 0:
        hi *= 2.0
    alpha = float(optimize.brentq(log_pfa, 0.0, hi, xtol=1e-13, rtol=1e-14, maxiter=500))
    if min(m for m in sizes if m > 0) / alpha < _GRID_FLOOR * 1e3:  # mass below the grid
        raise OptionError(
            f"pfa={pfa:g} is too small for the {'GO' if reduce == 'max' else 'SO'} threshold "
            f"with blocks of {sorted(sizes)} cells (the factor would exceed {alpha:.3g}); "
            f"use a larger pfa"
        )
    return alpha


def keyed_factor_map(keys: Tensor, factor: Callable[[tuple[int, ...]], float]) -> Tensor:
    """Evaluate ``factor(key)`` at every distinct row of integer ``keys`` ``(..., k)``.

    Rows are packed into one int64 code (each entry must be in ``[0, 2^(63 // k))``) and
    ``factor`` is called once per distinct code.

    Args:
        keys: float or int tensor ``(..., k)`` of integer-valued entries (e.g. block sizes).
        factor: ``factor(tuple_of_ints) -> float`` (cache it).

    Returns:
        float64 tensor ``keys.shape[:-1]``.

    Examples:
        >>> keyed_factor_map(torch.tensor([[1, 2], [3, 4], [1, 2]]), lambda k: k[0] + k[1]).tolist()
        [3.0, 7.0, 3.0]
    """
    k = keys.round().long().clamp_min(0)
    bits = 63 // k.shape[-1]
    code = torch.zeros(k.shape[:-1], dtype=torch.long, device=k.device)
    for i in range(k.shape[-1]):
        code = code | (k[..., i] << (bits * i))
    if code.numel() == 0:
        return torch.zeros(code.shape, dtype=torch.float64, device=k.device)
    uniq, inv = torch.unique(code.flatten(), return_inverse=True)
    mask = (1 << bits) - 1
    rows = [tuple((c >> (bits * i)) & mask for i in range(k.shape[-1])) for c in uniq.tolist()]
    table = torch.tensor([factor(r) for r in rows], dtype=torch.float64)
    return table.to(k.device)[inv].reshape(code.shape)


@lru_cache(maxsize=4096)
def student_factor(n: int, pfa: float) -> float:
    """``t_{n-1}^{-1}(1 - pfa) sqrt(1 + 1/n)``: the exact prediction-interval factor of a new
    normal sample from ``n`` samples (mean and unbiased standard deviation)."""
    from scipy import stats

    if n <= 1:
        return math.inf
    return float(stats.t.ppf(1.0 - pfa, n - 1) * math.sqrt(1.0 + 1.0 / n))
