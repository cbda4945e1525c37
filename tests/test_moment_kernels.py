"""The window moments of the one-sweep speckle kernels (:mod:`torchsar._moment_kernels`)
against sums by ``math.fsum`` at every pixel, borders included: the variance within
``2^-38`` of the exact one, relative, on clutter, on windows just above the near-flat
limit (where ``sum x^2 - (sum x)^2 / n`` cancels most) and on near-flat windows (summed
again as deviations: cancellation there would leave nothing of the variance); 0 exactly on
windows of equal cells. And the enhanced filters' heterogeneity (one square root, one
division) against its definition."""

from __future__ import annotations

import math

import numpy as np
import pytest

from torchsar import _jit

pytestmark = pytest.mark.skipif(not _jit.enabled(), reason="numba kernels not available")


def _kernel_moments(x: np.ndarray, radius: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance of every pixel of the plane ``x`` by the kernels, row by row."""
    from torchsar import _moment_kernels as mk

    h, w = x.shape
    cache, pad, sums = mk.moment_buffers(radius, w)
    cols = np.array([min(j + radius, w - 1) - max(j - radius, 0) + 1 for j in range(w)], float)
    counts = np.zeros((4, w))
    mu, var = np.zeros((h, w)), np.zeros((h, w))
    mk.prime(cache, x, radius)
    last = -1
    for i in range(h):
        mk.next_row(cache, x, i, radius)
        last = mk.window_counts(i, h, radius, cols, 1.0, last, counts)
        mk.row_moments(cache, pad, sums, i, h, radius, cols, counts[1], mu[i], var[i])
    return mu, var


def _exact_moments(x: np.ndarray, radius: int) -> tuple[np.ndarray, np.ndarray]:
    """The same by ``math.fsum`` over each window's in-image cells: the mean of the cells;
    the variance from their deviations ``d`` from the first cell (exact where the cells are
    close, as in the near-flat windows), the mean of ``d`` first, then the squares of ``d``
    minus it (an error ``e`` of that mean adds only ``e^2`` to the variance)."""
    h, w = x.shape
    mu, var = np.zeros((h, w)), np.zeros((h, w))
    for i in range(h):
        for j in range(w):
            cells = x[max(i - radius, 0) : i + radius + 1, max(j - radius, 0) : j + radius + 1]
            cells = cells.astype(np.float64).ravel().tolist()
            d = [c - cells[0] for c in cells]
            m = math.fsum(d) / len(d)
            mu[i, j] = math.fsum(cells) / len(cells)
            var[i, j] = math.fsum((e - m) ** 2 for e in d) / len(d)
    return mu, var


def _planes(seed: int, shape: tuple[int, int] = (13, 17)) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    clutter = rng.exponential(size=shape)
    clutter[4, 5] = 1e12  # a target among clutter
    offset = 1e6 * (1.0 + rng.exponential(size=shape) / 14.0)  # Ci^2 ~ 1/196: above 2^-8
    near_flat = 1e8 + rng.uniform(0.0, 1e-3, size=shape)  # Ci ~ 3e-12: cancels to nothing
    tail = 1e8 + rng.exponential(1e-3, size=shape)  # near-flat, some centres far out
    tail[6, 8] = 1e8 + 0.05  # one far out: its window is summed in two passes
    mixed = rng.exponential(size=shape)
    mixed[:, :6] = 0.0  # zeros beside clutter
    mixed[6:, 9:] = 2.5  # equal cells
    return {
        "clutter": clutter,
        "offset": offset,
        "near_flat": near_flat,
        "near_flat_tail": tail,
        "mixed": mixed,
    }


@pytest.mark.parametrize("radius", [1, 2, 3, 4, 7, 15])
@pytest.mark.parametrize("kind", ["clutter", "offset", "near_flat", "near_flat_tail", "mixed"])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_variance_is_within_2_to_the_minus_38(radius, kind, dtype):
    shape = (13, 17) if radius < 15 else (33, 35)  # whole 31 x 31 windows too
    x = _planes(radius, shape)[kind].astype(dtype)
    mu, var = _kernel_moments(x, radius)
    want_mu, want_var = _exact_moments(x, radius)
    np.testing.assert_allclose(mu, want_mu, rtol=2.0**-45, atol=0)
    zero = want_var == 0
    assert (var[zero] == 0).all()  # equal cells: 0 exactly
    rel = np.abs(var[~zero] - want_var[~zero]) / want_var[~zero]
    assert rel.max(initial=0.0) <= 2.0**-38, (kind, rel.max())


def test_equal_cells_give_zero_variance_wherever_they_lie():
    x = np.full((9, 12), 3.25)
    x[:, 8:] = 1e30
    for radius in (1, 2, 3):
        mu, var = _kernel_moments(x, radius)
        inside = np.zeros_like(x, bool)
        inside[:, : 8 - radius] = True  # windows of 3.25 alone
        assert (var[inside] == 0).all() and (mu[inside] == 3.25).all()


def _heterogeneity_definition(mu, var, n, cu, cmax, damping):
    """``damping (Ci - Cu) / (Cmax - Ci)`` between ``Cu`` and ``Cmax``, 0 at or below ``Cu``,
    ``inf`` at or above ``Cmax``; ``Ci^2 = var / mu^2`` clamped to ``[0, n - 1]``."""
    ci2 = var / (mu * mu) if mu > 0 else (0.0 if var == 0 else math.inf)
    ci = math.sqrt(min(ci2, n - 1.0))
    if ci <= cu:
        return 0.0
    if ci >= cmax:
        return math.inf
    return damping * (ci - cu) / (cmax - ci)


def test_a_large_near_flat_window_with_an_outlier_centre_keeps_its_precision():
    """The near-flat sum is two passes over the deviations: a 31 x 31 window of values near
    1 whose squares all round the same way, with a 0 at its centre (centring on the pixel
    then removes nothing), keeps the variance within 2^-38 (one pass over the squares of
    the deviations lost 2^-35.5 here)."""
    from fractions import Fraction

    rng = np.random.default_rng(0)
    x = 1.0 + rng.integers(2**17, 2**22, size=200000) * 2.0**-43
    frac = (x * x / 2.0**-43) % 1.0
    img = x[(frac > 0.40) & (frac < 0.49)][:961].reshape(31, 31).copy()
    img[15, 15] = 0.0
    _, var = _kernel_moments(img, 15)
    cells = [Fraction(v) for v in img.ravel()]
    mean = sum(cells) / len(cells)
    want = float(sum((c - mean) ** 2 for c in cells) / len(cells))
    assert abs(var[15, 15] - want) / want <= 2.0**-38


def test_heterogeneity_is_its_definition():
    from torchsar._moment_kernels import heterogeneity

    rng = np.random.default_rng(3)
    looks = 2.0
    cu, cmax = math.sqrt(1 / looks), math.sqrt(1 + 2 / looks)
    cases = [(0.0, 0.0), (0.0, 1.0), (2.0, 0.0), (1.0, 0.5), (1.0, 2.0), (1.0, 48.0)]
    cases += [(m, (c * m) ** 2) for m in (0.3, 7.0) for c in (cu, cmax)]  # on the borders
    cases += [(b / 4, 3 * b * b / 16) for b in (12.437085151672363, 1.0, 3.3)]  # Ci^2 = 3
    cases += list(zip(rng.exponential(size=400), rng.exponential(size=400) * 3, strict=True))
    for n in (4.0, 49.0):
        for damping in (0.0, 1.0, 2.5):
            for mu, var in cases:
                got = heterogeneity(mu, var, n, cu, cmax, damping)
                want = _heterogeneity_definition(mu, var, n, cu, cmax, damping)
                assert got == want, (mu, var, n, damping, got, want)  # the same operations
