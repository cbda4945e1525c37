"""Slow, obvious references for the CFAR family: explicit loops over ring cells and blocks."""

from __future__ import annotations

import math

import numpy as np
from scipy import integrate, optimize, stats


def ring_cells(img: np.ndarray, i: int, j: int, guard: int, train: int) -> np.ndarray:
    """In-image ring cells around (i, j) (outer box minus guard box)."""
    h, w = img.shape
    o = guard + train
    return np.asarray(
        [
            img[i + a, j + b]
            for a in range(-o, o + 1)
            for b in range(-o, o + 1)
            if max(abs(a), abs(b)) > guard and 0 <= i + a < h and 0 <= j + b < w
        ],
        dtype=np.float64,
    )


def block_cells(img: np.ndarray, i: int, j: int, guard: int, train: int) -> list[np.ndarray]:
    """The 4 pinwheel blocks (top, right, bottom, left) written out cell by cell."""
    g, o = guard, guard + train
    h, w = img.shape

    def take(rows: range, cols: range) -> np.ndarray:
        return np.asarray(
            [img[i + a, j + b] for a in rows for b in cols if 0 <= i + a < h and 0 <= j + b < w],
            dtype=np.float64,
        )

    return [
        take(range(-o, -g), range(-o, g + 1)),
        take(range(-o, g + 1), range(g + 1, o + 1)),
        take(range(g + 1, o + 1), range(-g, o + 1)),
        take(range(-g, o + 1), range(-o, -g)),
    ]


def _ring_pixels(x: np.ndarray, guard: int, train: int, valid: np.ndarray | None = None):
    """Every pixel of ``x`` ``(B, C, H, W)``: its ``(idx, i, j)`` (``x[idx][i, j]``), its
    value and its in-image ring cells (only the ``valid`` ones, with a mask)."""
    for idx in np.ndindex(*x.shape[:2]):
        img = x[idx]
        ok = None if valid is None else np.where(valid[idx], 1.0, np.nan)
        for i in range(img.shape[0]):
            for j in range(img.shape[1]):
                cells = ring_cells(img, i, j, guard, train)
                if ok is not None:
                    cells = cells[~np.isnan(ring_cells(ok, i, j, guard, train))]
                yield idx, i, j, img[i, j], cells


def _over(value: float, mean: float) -> float:
    """``value / mean`` for a mean ``>= 0``: ``0 / 0 = 0``, ``inf`` above a zero mean."""
    return value / mean if mean > 0 else (0.0 if value == 0 else math.inf)


def ca_reference(
    x: np.ndarray, guard: int, train: int, pfa: float, valid: np.ndarray | None = None
) -> np.ndarray:
    """CA-CFAR's ``I / mean_ring`` over the in-image (and ``valid``) ring cells (summed
    exactly: ``math.fsum``), times the border factor, pixel by pixel, of ``x`` ``(B, C, H,
    W)``; ``0 / 0 = 0``; ``-inf`` where the pixel is not valid or its ring has no valid
    cell."""
    from torchsar.cfar.thresholds import ca_factor

    n = (2 * (guard + train) + 1) ** 2 - (2 * guard + 1) ** 2
    out = np.empty(x.shape)
    for idx, i, j, value, cells in _ring_pixels(x, guard, train, valid):
        if valid is not None and (not valid[idx][i, j] or cells.size == 0):
            out[idx][i, j] = -math.inf
            continue
        v = _over(value, math.fsum(cells) / len(cells))
        out[idx][i, j] = v * (1.0 / ca_factor(len(cells), pfa)) * ca_factor(n, pfa)
    return out


def two_parameter_reference(
    x: np.ndarray, guard: int, train: int, valid: np.ndarray | None = None
) -> np.ndarray:
    """The two-parameter CFAR's ``(I - mean) / sigma`` over the in-image (and ``valid``)
    ring cells (mean and population variance summed exactly: ``math.fsum``), ``+inf`` /
    ``-inf`` / 0 above, below or at the mean of a ring without variance, pixel by pixel, of
    ``x`` ``(B, C, H, W)``; ``-inf`` where the pixel is not valid or its ring has no valid
    cell."""
    out = np.empty(x.shape)
    for idx, i, j, value, cells in _ring_pixels(x, guard, train, valid):
        if valid is not None and (not valid[idx][i, j] or cells.size == 0):
            out[idx][i, j] = -math.inf
            continue
        if (cells == cells[0]).all():  # exactly: fsum / n need not give the value back
            mean, sigma = float(cells[0]), 0.0
        else:
            mean = math.fsum(cells) / len(cells)
            sigma = math.sqrt(math.fsum((cells - mean) ** 2) / len(cells))
        dev = value - mean
        if sigma > 0:
            out[idx][i, j] = dev / sigma
        else:
            out[idx][i, j] = math.copysign(math.inf, dev) if dev else 0.0
    return out


def ac_reference(
    x: np.ndarray,
    guard: int,
    train: int,
    pfa: float,
    limit: np.ndarray,
    mu: np.ndarray,
    valid: np.ndarray | None = None,
) -> np.ndarray:
    """AC-CFAR's ``I / mean`` over the (``valid``) ring cells at or below each plane's
    ``limit`` (summed exactly: ``math.fsum``), times ``factor(N) / factor(c)`` for ``c`` such
    cells, or ``I / mu * alpha / ln(1 / pfa)`` where every ring cell is censored, pixel by
    pixel, of ``x`` ``(B, C, H, W)`` (``limit``, ``mu``: ``(B, C)``); ``-inf`` where the
    pixel is not valid."""
    from torchsar.cfar.thresholds import ca_factor

    n = (2 * (guard + train) + 1) ** 2 - (2 * guard + 1) ** 2
    alpha = ca_factor(n, pfa)
    out = np.empty(x.shape)
    for idx, i, j, value, cells in _ring_pixels(x, guard, train, valid):
        kept = cells[cells <= limit[idx]]
        if valid is not None and not valid[idx][i, j]:
            out[idx][i, j] = -math.inf
        elif kept.size == 0:
            out[idx][i, j] = value / mu[idx] * (alpha / math.log(1.0 / pfa))
        else:
            v = _over(value, math.fsum(kept) / kept.size)
            out[idx][i, j] = v * (alpha / ca_factor(kept.size, pfa))
    return out


def block_reference(
    x: np.ndarray,
    guard: int,
    train: int,
    pfa: float,
    reduce: str,
    valid: np.ndarray | None = None,
) -> np.ndarray:
    """GO's (``reduce="max"``) or SO's ``I / extreme block mean`` over the in-image (and
    ``valid``) cells of the four pinwheel blocks (each mean summed exactly: ``math.fsum``;
    GO's estimate at least 0, SO's 0 where no block has cells; ``0 / 0 = 0``), times
    ``factor(interior) / factor(sizes)`` where a pixel's block sizes are not the interior's,
    ``-inf`` where no block has a cell or the pixel is not valid, pixel by pixel, of ``x``
    ``(B, C, H, W)``."""
    from torchsar.cfar.thresholds import block_factor

    size = train * (2 * guard + train + 1)
    interior = block_factor((size,) * 4, pfa, reduce)
    out = np.empty(x.shape)
    for idx in np.ndindex(*x.shape[:2]):
        img = x[idx]
        ok = None if valid is None else np.where(valid[idx], 1.0, np.nan)
        for i in range(img.shape[0]):
            for j in range(img.shape[1]):
                blocks = block_cells(img, i, j, guard, train)
                if ok is not None:
                    keep = block_cells(ok, i, j, guard, train)
                    blocks = [b[~np.isnan(k)] for b, k in zip(blocks, keep, strict=True)]
                sizes = tuple(len(b) for b in blocks)
                if sum(sizes) == 0 or (ok is not None and np.isnan(ok[i, j])):
                    out[idx][i, j] = -math.inf
                    continue
                means = [math.fsum(b) / len(b) for b in blocks if len(b)]
                est = max(max(means), 0.0) if reduce == "max" else min(means)
                v = img[i, j] / est if est > 0 else (0.0 if img[i, j] == 0 else math.inf)
                if sizes != (size,) * 4:
                    v = v * (interior / block_factor(tuple(sorted(sizes)), pfa, reduce))
                out[idx][i, j] = v
    return out


def os_reference(
    x: np.ndarray, guard: int, train: int, rank: int, factor, dtype=np.float32
) -> np.ndarray:
    """OS-CFAR's statistic pixel by pixel of ``x`` ``(B, C, H, W)``: the ``r_n``-th smallest
    in-image ring value by sorting (``r_n = round(rank n / N)``, at least 1), ``I / x_(r_n)``
    in float64 (``0 / 0 = 0``), times ``(1 / factor(n)) * factor(N)`` where ``n != N``, cast
    to ``dtype``."""
    n_full = (2 * (guard + train) + 1) ** 2 - (2 * guard + 1) ** 2
    out = np.empty(x.shape, dtype=dtype)
    for idx in np.ndindex(*x.shape[:2]):
        img = x[idx].astype(np.float64)
        for i in range(img.shape[0]):
            for j in range(img.shape[1]):
                cells = ring_cells(img, i, j, guard, train)
                n = len(cells)
                r = min(n, max(1, round(rank * n / n_full)))
                est = kth_smallest(cells, r)
                with np.errstate(divide="ignore", invalid="ignore"):
                    v = np.float64(img[i, j]) / (np.float64(est) + 0.0)  # -0.0 is zero
                v = 0.0 if v != v else v
                if n != n_full:
                    v = v * ((1.0 / factor(n)) * factor(n_full))
                out[idx][i, j] = v
    return out


def kth_smallest(cells: np.ndarray, k: int) -> float:
    return float(np.sort(cells)[k - 1])


def os_alpha(n: int, rank: int, pfa: float) -> float:
    """Rohling's product formula solved with a generic root finder."""

    def f(a: float) -> float:
        return math.prod((n - i) / (n - i + a) for i in range(rank)) - pfa

    return optimize.brentq(f, 0.0, 1e7, xtol=1e-12)


def block_alpha(m: int, blocks: int, pfa: float, reduce: str) -> float:
    """GO/SO factor for ``blocks`` equal blocks of ``m`` exponential cells, by adaptive
    quadrature of ``E[exp(-alpha Z)]`` over the density of the max / min block mean."""
    law = stats.gamma(m, scale=1.0 / m)

    def density(z: float) -> float:
        f, cdf = law.pdf(z), law.cdf(z)
        other = cdf if reduce == "max" else 1.0 - cdf
        return blocks * f * other ** (blocks - 1)

    def pfa_of(a: float) -> float:
        return integrate.quad(lambda z: math.exp(-a * z) * density(z), 0, np.inf, limit=400)[0]

    return optimize.brentq(lambda a: math.log(pfa_of(a) / pfa), 1e-3, 1e4, xtol=1e-10)


def exceedance(stat: np.ndarray, threshold: float) -> float:
    return float(np.mean(stat > threshold))


def sample_clutter(
    model: str,
    shape: tuple[int, ...],
    seed: int,
    looks: float = 1.0,
    shape_param: float | None = None,
) -> np.ndarray:
    """Unit-mean intensity clutter drawn with numpy (the simulator's parameterisation:
    K texture ``Gamma(nu, 1/nu)``, G0 texture ``(a - 1) / Gamma(a)``, log-normal
    ``exp(s Z - s^2 / 2)``, Weibull ``lam E^(1/c)``)."""
    rng = np.random.default_rng(seed)
    speckle = rng.gamma(looks, 1.0 / looks, size=shape)
    if model in ("exponential", "gamma"):
        return speckle
    if model == "k":
        nu = 2.0 if shape_param is None else shape_param
        return speckle * rng.gamma(nu, 1.0 / nu, size=shape)
    if model == "g0":
        a = 3.0 if shape_param is None else shape_param
        return speckle * (a - 1.0) / rng.gamma(a, size=shape)
    if model == "lognormal":
        s = 1.0 if shape_param is None else shape_param
        return np.exp(s * rng.standard_normal(shape) - s * s / 2)
    c = 0.8 if shape_param is None else shape_param
    return rng.exponential(size=shape) ** (1.0 / c) / math.gamma(1.0 + 1.0 / c)


def vi_statistic(
    img: np.ndarray,
    valid: np.ndarray,
    i: int,
    j: int,
    guard: int,
    train: int,
    pfa: float,
    k_vi: float,
    k_mr: float,
) -> float:
    """VI-CFAR statistic at (i, j) written out: Smith & Varshney's rule on the two halves of
    the counted ring cells, each rule with its exact factor for its own half sizes, scaled to
    the interior CA factor."""
    from torchsar.cfar.thresholds import block_factor, ca_factor

    blocks = block_cells(np.where(valid, img, np.nan), i, j, guard, train)
    a = np.concatenate(blocks[:2])
    b = np.concatenate(blocks[2:])
    a, b = a[~np.isnan(a)], b[~np.isnan(b)]

    def variable(x: np.ndarray) -> bool:
        return x.size <= 1 or 1 + x.var(ddof=1) / x.mean() ** 2 > k_vi

    va, vb = variable(a), variable(b)
    n_full = len(
        ring_cells(
            np.ones((4 * (guard + train) + 1,) * 2),
            2 * (guard + train),
            2 * (guard + train),
            guard,
            train,
        )
    )
    full = ca_factor(n_full, pfa)
    if a.size == 0 or b.size == 0:  # one half empty: CA on the other
        c = a if a.size else b
        est, alpha = c.mean(), ca_factor(c.size, pfa)
    elif va and vb:
        est, alpha = (
            min(a.mean(), b.mean()),
            block_factor(tuple(sorted((a.size, b.size))), pfa, "min"),
        )
    elif va:
        est, alpha = b.mean(), ca_factor(b.size, pfa)
    elif vb:
        est, alpha = a.mean(), ca_factor(a.size, pfa)
    elif a.mean() > k_mr * b.mean() or b.mean() > k_mr * a.mean():
        est, alpha = (
            max(a.mean(), b.mean()),
            block_factor(tuple(sorted((a.size, b.size))), pfa, "max"),
        )
    else:
        est, alpha = np.concatenate([a, b]).mean(), ca_factor(a.size + b.size, pfa)
    return float(img[i, j] / est * full / alpha)


def zero_blocks_scene(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """An ``(1, 1, h, w)`` exponential clutter plane with two bright targets (up to 1e12
    times the clutter: a plane mean far from the clutter) and two blocks of exact zeros,
    drawn from ``rng``: where sums of deviations from the plane's mean leave residues."""
    img = rng.exponential(rng.uniform(0.1, 100.0), (1, 1, h, w))
    for _ in range(2):
        r, c = rng.integers(0, h - 3), rng.integers(0, w - 3)
        img[0, 0, r : r + 3, c : c + 3] = 10 ** rng.uniform(3, 12)
        r, c = rng.integers(0, h - 10), rng.integers(0, w - 10)
        img[0, 0, r : r + int(rng.integers(4, 10)), c : c + int(rng.integers(4, 10))] = 0.0
    return img
