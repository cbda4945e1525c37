"""Shared machinery of the distribution CFARs: per-pixel ring log-cumulants (or moments),
the fitted clutter law's ``(1 - pfa)`` quantile, and the statistic ``I / quantile``.

Zeros (log-domain laws: lognormal, Weibull, K, G0): ``ln 0 = -inf`` carries no information on
the clutter law, and on quantised data (8-bit magnitude: every value below half a grey level
reads 0) an exact zero stands for "below the quantisation step", not for a value. A single
zero clamped to any finite floor dominates the ring's log-variance (one cell at ``ln 1e-38``
among values near ``ln 1e-2`` inflates ``k2`` a hundredfold, so nothing is ever detected).
Zero cells are therefore left out of the ring's log-cumulant fit through the ``valid``
mechanism (censored, like no-data cells; the fit uses the ring's positive cells and the
tables of its own cell count ``n``). A zero cell under test is still tested: its statistic
is ``0 / q = 0``. A ring with fewer than 2 positive cells cannot be fitted and gives
``-inf``. Images without zeros (any continuous clutter) are processed exactly as before.
The censoring biases the fit slightly towards the positive cells (a fraction ``p0`` of zeros
shifts ``k1`` by about ``p0 (k1 - ln q0)``, ``q0`` the quantisation step), which is
negligible when zeros are rare and conservative (fewer alarms) otherwise.

Statistic convention (all distribution CFARs): ``statistic = I / q``, where ``q`` is the
``(1 - pfa)`` quantile of the clutter law fitted to the pixel's ring; ``threshold = 1``.
So ``mask == statistic > 1`` is the design test, and sweeping the threshold ``tau`` scales
every pixel's fitted quantile by ``tau`` (monotone per pixel), which keeps ROC sweeps
meaningful.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from torch import Tensor

from torchsar import _jit
from torchsar._checks import check_image, check_positive, check_probability
from torchsar.cfar.core import conclude, finish, out_dtype, prepare, ratio, valid_planes
from torchsar.cfar.log_t import LOG_T_SHAPES, log_t_table, trigamma_table
from torchsar.detection import Detection
from torchsar.windows import Ring, Sums, strip_rows, windowed

__all__ = [
    "distribution_cfar",
    "distribution_threshold",
    "log_cumulants",
    "log_t_quantile",
    "shape_from_spread",
]


def distribution_cfar(
    x: Tensor,
    guard: int,
    train: int,
    pfa: float,
    valid: Tensor | None,
    quantile: Callable[[Sums, float], Tensor],  # (ring sums, pfa) -> float64 quantile
    *,
    log_domain: bool,
    detector: str,
) -> Detection:
    """Run the distribution CFAR ``detector`` (its name, for messages): ring sums of
    ``ln I`` (``log_domain``) or ``I``, the fitted quantile per pixel, statistic ``I / q``,
    threshold 1. Rings with fewer than 2 cells cannot be fitted and give ``-inf``."""
    ring, pfa, vmask = prepare(x, guard, train, pfa, valid, detector=detector, values=False)
    check_image(x, "x")  # the values last, after every option (the law's own come first)
    dtype = out_dtype(x)
    src = _safe_log(x) if log_domain else x
    fit = _positive_cells(x, vmask) if log_domain else vmask

    def statistic(_src: Tensor, sums: list[Sums], xs: Tensor) -> Tensor:
        q = quantile(sums[0], pfa)
        stat = ratio(xs.to(torch.float64), q)
        return finish(stat, sums[0].count - 1, dtype)

    if _jit.for_tensor(src) and src.numel():
        stat = _compiled_fit(x, src, fit, ring, statistic)
    else:
        stat = windowed(src, [ring.region], statistic, valid=fit, moments=2, extras=(x,))
    return conclude(stat, vmask, distribution_threshold(guard=guard, train=train, pfa=pfa))


def _compiled_fit(
    x: Tensor,
    src: Tensor,
    fit: Tensor | None,
    ring: Ring,
    statistic: Callable[[Tensor, list[Sums], Tensor], Tensor],
) -> Tensor:
    """The ring moments of ``src`` on the CPU in one sweep per strip of rows
    (:func:`torchsar._box_kernels.ring_moments`: the ring sums of the values and their
    squares in row blocks, near-flat rings again from their cells, so a ring of equal
    cells has a variance of exactly 0), handed to ``statistic`` as :class:`Sums` of
    deviations from the ring's own mean (``s1 = 0``, ``s2 = n var``), strip by strip."""
    from torchsar import _box_kernels

    b, c, h, w = src.shape
    planes = src.detach().reshape(-1, h, w).to(torch.float64).contiguous().numpy()
    valid = valid_planes(fit, src)
    rows = strip_rows(src, ring.outer)
    out = None
    for r in range(0, h, rows):
        rr = min(rows, h - r)
        count, mean, var = (np.empty((b * c, rr, w)) for _ in range(3))
        _box_kernels.ring_moments(
            planes, valid, fit is not None, ring.guard, ring.train, r, count, mean, var
        )
        n = torch.from_numpy(count).view(b, c, rr, w)
        spread = torch.from_numpy(var).view(b, c, rr, w).mul_(n)
        sums = Sums(n, torch.zeros_like(n), spread, torch.from_numpy(mean).view(b, c, rr, w))
        part = statistic(src[..., r : r + rr, :], [sums], x[..., r : r + rr, :])
        if out is None:
            out = part.new_empty((b, c, h, w))
        out[..., r : r + rr, :] = part
    return out


def distribution_threshold(*, guard: int, train: int, pfa: float, looks: float = 1.0) -> float:
    """The design threshold of every distribution CFAR: 1 (the fitted quantile is in the
    statistic), whatever the valid options (``looks``, for the laws that have it, is only
    validated)."""
    Ring(guard, train)
    check_probability(pfa, "pfa")
    check_positive(looks, "looks")
    return 1.0


def _safe_log(x: Tensor) -> Tensor:
    """``ln I`` with zeros clamped to the dtype's smallest normal number (finite; zero cells
    never enter a fit, see :func:`_positive_cells`)."""
    return torch.log(x.clamp_min(torch.finfo(x.dtype).tiny))


def _positive_cells(x: Tensor, vmask: Tensor | None) -> Tensor | None:
    """The cells a log-domain ring fit may use: valid and ``> 0`` (zeros are censored, see
    the module docstring); ``vmask`` unchanged when ``x`` has no zero."""
    zero = x == 0
    if not bool(zero.any()):
        return vmask
    return ~zero if vmask is None else vmask.expand_as(x) & ~zero


def log_cumulants(s: Sums) -> tuple[Tensor, Tensor]:
    """First two sample log-cumulants of the ring: mean and unbiased variance of ``ln I``."""
    return s.mean(), s.var(unbiased=True)


def shape_from_spread(y: Tensor) -> Tensor:
    """Solve ``psi_1(shape) = y`` (inverse trigamma) on the log-t shape range, clamped to it:
    a spread at or below ``psi_1(max)`` gives the largest shape (the speckle-only limit).
    Vectorised interpolation of a fine ``log psi_1`` table (relative error < 1e-5)."""
    s_tab, l_tab = (torch.tensor(v, dtype=torch.float64, device=y.device) for v in trigamma_table())
    inc, s_inc = l_tab.flip(0), s_tab.flip(0)  # log psi_1 increases as the shape decreases
    ly = y.to(torch.float64).clamp_min(1e-300).log().clamp(inc[0], inc[-1])
    i = torch.searchsorted(inc, ly.contiguous()).clamp(1, inc.numel() - 1)
    frac = (ly - inc[i - 1]) / (inc[i] - inc[i - 1])
    return (s_inc[i - 1] + frac * (s_inc[i] - s_inc[i - 1])).exp()


def log_t_quantile(s: Sums, pfa: float, law: str, looks: float) -> Tensor:
    """``q = exp(k1 + t sqrt(k2))`` with the calibrated ``t`` of
    :func:`~torchsar.cfar.log_t.log_t_table` for each pixel's ring size and (K / G0) its
    shape, estimated from ``k2 - psi_1(L)`` by inverse trigamma and interpolated in
    ``log shape``."""
    k1, k2 = log_cumulants(s)
    n = s.count.round().long().clamp_min(2)
    present = torch.unique(n).tolist()  # one cached table per ring size
    rows = torch.tensor(
        [log_t_table(law, looks, pfa, m) for m in present], dtype=torch.float64, device=k1.device
    )
    row_of = torch.zeros(max(present) + 1, dtype=torch.long, device=k1.device)
    row_of[present] = torch.arange(len(present), device=k1.device)
    r = row_of[n]
    if law == "weibull":
        t = rows[r, 0]
    else:
        start, stop, pts = LOG_T_SHAPES
        speckle = float(torch.polygamma(1, torch.tensor(float(looks), dtype=torch.float64)))
        shape = shape_from_spread(k2 - speckle)
        pos = ((shape.log() - start) / ((stop - start) / (pts - 1))).clamp(0, pts - 1)
        i0 = pos.floor().long().clamp(max=pts - 2)
        t = rows[r, i0] * (1 - (pos - i0)) + rows[r, i0 + 1] * (pos - i0)
    return (k1 + t * k2.sqrt()).exp()
