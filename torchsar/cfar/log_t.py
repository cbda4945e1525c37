"""Log-t thresholds for the texture CFARs (K, G0) and Weibull: ``ln q = k1 + t sqrt(k2)``.

Why log-t: the ring's log-cumulants ``k1`` (mean of ``ln I``) and ``k2`` (unbiased variance)
carry the clutter's scale and spread. Plugging a shape estimated from ``k2`` into the
law's quantile amplifies the noise of ``k2`` through the inverse trigamma (the estimated
K / G0 shape of a 144-cell ring easily jumps to the gamma limit), and the realised
false-alarm rate doubles. Writing the threshold as ``k1 + t sqrt(k2)`` instead lets the
measured spread carry the scale of the test, and the standardised factor ``t`` hardly
depends on the shape (for K with L = 1 at Pfa 1e-3, ``t`` stays within 1.96-2.24 for every
``nu >= 0.5``), so the shape only needs to be roughly right.

Calibration: ``t`` solves ``E[S(e_bar + t s)] = pfa`` where ``S`` is the survival function
of the standardised log-intensity ``e = (ln I - kappa_1) / sqrt(kappa_2)`` of the law and
``(e_bar, s)``, the standardised sample mean and standard deviation of the ``n`` ring cells,
are taken as bivariate normal with their exact first and second moments from the law's
cumulants (``Var e_bar = 1/n``, ``Var s = (m4 - 1)/(4n)``, ``Cov = m3/(2n)``,
``E s = 1 - (m4 - 1)/(8n)``); the expectation uses a 2-D Gauss-Hermite rule. This accounts
for the estimation noise of location and spread to order ``1/n``.

Shape noise (K, G0): the detector reads ``t`` at the shape it *estimates* from the ring's
spread, and at one look a 144-cell ring barely tells G0 ``a = 3`` from the speckle limit
(with ``t`` fixed per true shape, G0 ``a = 3``, L = 1 ran at 3.3x the design rate at 1e-3 and
~10x at 1e-4). :func:`_adapt_to_shape_noise` therefore adds a smooth correction, fitted so
that the realised rate (same quadrature, with ``t`` read at the estimated shape of each
node) matches ``pfa`` across all true shapes of the grid, excesses weighted more than
deficits. It is a deterministic computation per ``(law, L, pfa, n)``, cached; measured rates
are in the tests and ``torchsar-eval pfa`` (G0 ``a = 3``, L = 1 still exceeds at 1e-4).

Laws (cumulants of ``ln I``, ``psi_k`` = polygamma): K ``(nu, L)``:
``kappa_j = psi_{j-1}(nu) + psi_{j-1}(L)`` (``j >= 2``); G0 ``(a, L)``:
``kappa_j = psi_{j-1}(L) + (-1)^j psi_{j-1}(a)``; Weibull: ``ln I = ln lam + ln(E)/c``, the
standardised law is that of ``ln E`` for every ``c``.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from scipy import optimize, special

from torchsar import _disk_cache

__all__ = ["LOG_T_SHAPES", "log_t_exact", "log_t_table", "trigamma_table"]

LOG_T_SHAPES = (math.log(0.05), math.log(1000.0), 41)
"""``(log start, log stop, points)`` of the shape grid of the log-t tables."""

_GH_Z, _GH_W = np.polynomial.hermite_e.hermegauss(16)
_GH_W = _GH_W / _GH_W.sum()


def _shapes() -> np.ndarray:
    return np.exp(np.linspace(*LOG_T_SHAPES))


def _cumulants(law: str, shape: float, looks: float) -> tuple[float, float, float, float]:
    """``kappa_1..kappa_4`` of ``ln I`` (unit texture mean for K, unit scale for G0)."""
    pg = special.polygamma
    if law == "weibull":
        return (float(special.digamma(1.0)), *(float(pg(j, 1.0)) for j in (1, 2, 3)))
    if law == "k":
        k1 = special.digamma(shape) - math.log(shape) + special.digamma(looks) - math.log(looks)
        return (float(k1), *(float(pg(j, shape) + pg(j, looks)) for j in (1, 2, 3)))
    k1 = special.digamma(looks) - math.log(looks) - special.digamma(shape)
    return (float(k1), *(float(pg(j, looks) + (-1) ** (j + 1) * pg(j, shape)) for j in (1, 2, 3)))


def _log_survival(law: str, shape: float, looks: float, log_u: np.ndarray) -> np.ndarray:
    """``ln P(I > u)`` at ``u = exp(log_u)`` for the law with the cumulants above."""
    u = np.exp(log_u)
    if law == "weibull":
        return -u
    if law == "g0":
        from scipy import stats  # slow to import: only the G0 law needs it

        return stats.f.logsf(shape * u, 2.0 * looks, 2.0 * shape)
    s = np.linspace(math.log(1e-10), math.log(max(80.0 / shape, 80.0)), 701)
    xs = np.exp(s)
    w = np.exp(shape * math.log(shape) + shape * s - shape * xs - special.gammaln(shape))
    w *= s[1] - s[0]
    tail = special.gammaincc(looks, looks * u[:, None] / xs[None, :]) @ w
    return np.log(np.maximum(tail, 1e-300))


_ANCHORS = (2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512, 1024, 4096)


def log_t_table(law: str, looks: float, pfa: float, n: int) -> tuple[float, ...]:
    """:func:`log_t_exact` at ``n`` interpolated linearly in ``1/n`` between the nearest
    anchor sizes (exact at the anchors; the noise terms are ``O(1/n)``). Sizes above the
    last anchor use it."""
    if n in _ANCHORS or n >= _ANCHORS[-1]:
        return log_t_exact(law, looks, pfa, min(n, _ANCHORS[-1]))
    hi = next(a for a in _ANCHORS if a > n)
    lo = max(a for a in _ANCHORS if a < n)
    w = (1 / n - 1 / hi) / (1 / lo - 1 / hi)
    a, b = log_t_exact(law, looks, pfa, lo), log_t_exact(law, looks, pfa, hi)
    return tuple(w * x + (1 - w) * y for x, y in zip(a, b, strict=True))


@lru_cache(maxsize=1024)
def log_t_exact(law: str, looks: float, pfa: float, n: int) -> tuple[float, ...]:
    """Calibrated log-t factor ``t`` for rings of ``n`` cells at design ``pfa``.

    Weibull: one value (the standardised law is shape-free). K / G0: one value per shape of
    :data:`LOG_T_SHAPES`. A deterministic computation of about half a second, kept in
    memory and on disk (``~/.cache/torchsar``; ``TORCHSAR_CACHE`` sets the folder, ``0``
    turns it off), so each machine pays it once per ``(law, looks, pfa, n)``.

    Examples:
        >>> t = log_t_exact("weibull", 1.0, 1e-3, 10**9)[0]  # n -> inf: the Gumbel quantile
        >>> round(t, 3) == round((math.log(math.log(1e3)) + 0.5772156649) / (math.pi / 6**0.5), 3)
        True
    """
    if _VERSION is None:
        return _compute(law, looks, pfa, n)
    key = f"{law}|{float(looks)!r}|{float(pfa)!r}|{int(n)}|{_VERSION}"
    hit = _disk_cache.load("log_t", key)
    if hit is not None:
        return hit
    out = _compute(law, looks, pfa, n)
    _disk_cache.store("log_t", key, out)
    return out


_VERSION = _disk_cache.version_of(__file__)
"""This module's version tag in the on-disk cache of the factors (code, numpy, scipy)."""


def _compute(law: str, looks: float, pfa: float, n: int) -> tuple[float, ...]:
    """:func:`log_t_exact` without the caches."""
    shapes = 1 if law == "weibull" else LOG_T_SHAPES[2]
    out = []
    for j in range(shapes):
        f = lambda t, j=j: _log_pfa(law, looks, j, n, t) - math.log(pfa)  # noqa: E731
        out.append(_root(f, -1.0, 13.0))
    if law == "weibull":
        return tuple(out)
    return tuple(_adapt_to_shape_noise(law, looks, pfa, n, np.array(out)).tolist())


def _root(f, lo: float, hi: float) -> float:
    """Brent's root of a decreasing ``f`` on ``[lo, hi]``, clipped to the bracket (tiny rings
    of very heavy-tailed laws cannot reach the design rate inside it)."""
    if f(hi) > 0:
        return hi
    if f(lo) < 0:
        return lo
    return float(optimize.brentq(f, lo, hi, xtol=1e-8))


@lru_cache(maxsize=16)
def _tails(law: str, looks: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Standardised grid ``e``, ``ln S(e)`` per shape ``(J, E)`` and cumulants ``(J, 4)``."""
    shapes = [1.0] if law == "weibull" else _shapes()
    e = np.linspace(-2.0, 14.0, 321)
    kap = np.array([_cumulants(law, float(a), looks) for a in shapes])
    logs = np.stack(
        [
            _log_survival(law, float(a), looks, k[0] + e * math.sqrt(k[1]))
            for a, k in zip(shapes, kap, strict=True)
        ]
    )
    return e, logs, kap


def _log_pfa(law: str, looks: float, j: int, n: int, t: float) -> float:
    """``ln E[S_j(e_bar + t s)]`` for shape ``j`` of the grid, ``(e_bar, s)`` bivariate
    normal with the moments given in the module docstring (2-D Gauss-Hermite)."""
    e, log_s, kap = _tails(law, looks)
    m3, m4 = kap[j, 2] / kap[j, 1] ** 1.5, kap[j, 3] / kap[j, 1] ** 2 + 3.0
    sd_m, sd_s = 1.0 / math.sqrt(n), math.sqrt(max(m4 - 1.0, 1e-12) / (4.0 * n))
    rho = float(np.clip((m3 / (2.0 * n)) / (sd_m * sd_s), -0.99, 0.99))
    z1, z2 = _GH_Z[:, None], _GH_Z[None, :]
    spread = 1.0 - (m4 - 1.0) / (8.0 * n) + sd_s * (rho * z1 + math.sqrt(1 - rho**2) * z2)
    ls = np.interp(sd_m * z1 + t * np.maximum(spread, 0.0), e, log_s[j])
    return math.log(max(float(np.sum(_GH_W[:, None] * _GH_W[None, :] * np.exp(ls))), 1e-300))


@lru_cache(maxsize=4)
def trigamma_table() -> tuple[tuple[float, ...], tuple[float, ...]]:
    """``(log shape, log psi_1(shape))`` on a fine grid over the shape range, for the
    vectorised inverse trigamma of the shape estimate."""
    s = np.linspace(LOG_T_SHAPES[0], LOG_T_SHAPES[1], 4001)
    return tuple(s.tolist()), tuple(np.log(special.polygamma(1, np.exp(s))).tolist())


_GH_S, _GH_SW = np.polynomial.hermite_e.hermegauss(48)  # finer in the spread (the kink of
_GH_SW = _GH_SW / _GH_SW.sum()  # the shape estimate at the speckle limit)


def _shape_positions(law: str, looks: float, n: int) -> tuple[np.ndarray, ...]:
    """For every true shape ``j`` of the grid and every Gauss-Hermite node: the standardised
    ring mean and spread, and the grid position (``i0``, ``frac``) of the shape the detector
    estimates from that spread (inverse trigamma of ``k2 - psi_1(L)``, clamped to the grid
    as in :func:`torchsar.cfar.distribution.shape_from_spread`)."""
    kap = _tails(law, looks)[2]
    m3 = kap[:, 2] / kap[:, 1] ** 1.5
    m4 = kap[:, 3] / kap[:, 1] ** 2 + 3.0
    sd_m = 1.0 / math.sqrt(n)
    sd_s = np.sqrt(np.maximum(m4 - 1.0, 1e-12) / (4.0 * n))
    rho = np.clip((m3 / (2.0 * n)) / (sd_m * sd_s), -0.99, 0.99)[:, None, None]
    z1, z2 = _GH_Z[None, :, None], _GH_S[None, None, :]
    spread = (
        1.0
        - (m4[:, None, None] - 1.0) / (8.0 * n)
        + sd_s[:, None, None] * (rho * z1 + np.sqrt(1.0 - rho**2) * z2)
    )
    spread = np.maximum(spread, 0.0)
    y = spread**2 * kap[:, 1, None, None] - float(special.polygamma(1, looks))
    log_shape, log_psi = (np.array(v) for v in trigamma_table())
    ly = np.clip(np.log(np.maximum(y, 1e-300)), log_psi[-1], log_psi[0])
    a_hat = np.interp(ly, log_psi[::-1], log_shape[::-1])
    start, stop, pts = LOG_T_SHAPES
    pos = np.clip((a_hat - start) / ((stop - start) / (pts - 1)), 0, pts - 1)
    i0 = np.minimum(np.floor(pos).astype(int), pts - 2)
    return sd_m * z1, spread, i0, pos - i0


def _adapt_to_shape_noise(law: str, looks: float, pfa: float, n: int, t: np.ndarray) -> np.ndarray:
    """Correct the per-shape factors for the noise of the shape estimate.

    The detector does not know the shape: it reads ``t`` at the shape it estimates from the
    ring's spread, which for a 144-cell ring wanders over decades (and to the speckle limit
    whenever ``k2 < psi_1(L)``). The realised rate at true shape ``a_j`` is
    ``E[S_j(e_bar + t(a_hat(s)) s)]`` over the same bivariate normal ``(e_bar, s)``. A
    smooth correction ``delta(ln a_hat)`` (piecewise linear on :data:`_KNOTS` knots; the
    pointwise inverse problem is ill-posed) is fitted by damped Gauss-Newton so that the
    realised log-rate equals ``ln pfa`` at every true shape of the grid in least squares,
    an excess weighted :data:`_EXCESS_WEIGHT` times a deficit (where the ring cannot tell
    the shapes apart, the CFAR errs on the side of fewer false alarms). The corrected factor
    is capped at the largest uncorrected one (the heaviest-tailed shape's own ``t``): the
    smooth fit may not overshoot the worst case.
    Deterministic (quadrature, no Monte Carlo); it calibrates for the estimator's noise, not
    for any data set."""
    e, log_s, _ = _tails(law, looks)
    loc, spread, i0, frac = _shape_positions(law, looks, n)
    w = _GH_W[None, :, None] * _GH_SW[None, None, :]
    de = e[1] - e[0]
    rows = np.arange(len(t))[:, None, None]
    basis = _hat_basis(len(t), _KNOTS)

    def residual(c: np.ndarray) -> np.ndarray:
        tt = t + basis @ c
        th = tt[i0] * (1.0 - frac) + tt[i0 + 1] * frac
        u = np.clip((loc + th * spread - e[0]) / de, 0.0, len(e) - 1.000001)
        k = u.astype(int)
        ls = log_s[rows, k] * (1.0 - (u - k)) + log_s[rows, k + 1] * (u - k)
        r = np.log(np.maximum((w * np.exp(ls)).sum(axis=(1, 2)), 1e-300)) - math.log(pfa)
        return np.where(r > 0, _EXCESS_WEIGHT * r, r)  # an excess costs more than a deficit

    c = np.zeros(basis.shape[1])
    r, lam = residual(c), 1e-3
    for _ in range(40):  # Levenberg-Marquardt
        jac = np.stack([(residual(c + 1e-4 * ek) - r) / 1e-4 for ek in np.eye(len(c))], 1)
        step = np.linalg.solve(jac.T @ jac + lam * np.eye(len(c)), -jac.T @ r)
        r_new = residual(c + step)
        if np.sum(r_new**2) < np.sum(r**2):
            c, r, lam = c + step, r_new, lam / 3.0
        else:
            lam *= 10.0
    return np.clip(t + basis @ c, -1.0, t.max())  # never above the heaviest shape's own t


_KNOTS = 9
_EXCESS_WEIGHT = 3.0


def _hat_basis(points: int, knots: int) -> np.ndarray:
    """``(points, knots)`` piecewise-linear hat functions on equally spaced knots."""
    x = np.linspace(0.0, knots - 1.0, points)
    return np.maximum(0.0, 1.0 - np.abs(x[:, None] - np.arange(knots)[None, :]))
