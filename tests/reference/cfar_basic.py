"""Slow references for CA and two-parameter CFAR: the textbook formulas, cell by cell."""

from __future__ import annotations

import numpy as np
from scipy import stats

from tests.reference.windows import ring_cells


def ca_statistic(img: np.ndarray, i: int, j: int, guard: int, train: int) -> float:
    return img[i, j] / ring_cells(img, i, j, guard, train).mean()


def ca_alpha(n: int, pfa: float, looks: float = 1.0) -> float:
    """The (1 - pfa) quantile of I / mean_ring: F(2L, 2NL) for L-look gamma clutter."""
    return float(stats.f.ppf(1 - pfa, 2 * looks, 2 * n * looks))


def two_parameter_statistic(img: np.ndarray, i: int, j: int, guard: int, train: int) -> float:
    cells = ring_cells(img, i, j, guard, train)
    return (img[i, j] - cells.mean()) / cells.std()


def binomial_interval(n: int, p: float, z: float = 3.29) -> tuple[float, float]:
    """Normal-approximation interval of a binomial rate (default z: 99.9 %)."""
    half = z * np.sqrt(p * (1 - p) / n)
    return p - half, p + half
