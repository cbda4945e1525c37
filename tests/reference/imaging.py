"""Slow, obvious reference implementations for torchsar.imaging tests."""

from __future__ import annotations

import math

import numpy as np


def centred_dft_matrix(n: int) -> np.ndarray:
    """Dense unitary centred DFT matrix.

    ``D[k, i] = exp(-2j pi (k - n//2)(i - n//2) / n) / sqrt(n)``.
    """
    idx = np.arange(n) - n // 2
    return np.exp(-2j * math.pi * np.outer(idx, idx) / n) / math.sqrt(n)


def fft2c_dense(x: np.ndarray) -> np.ndarray:
    """Centred 2-D DFT of ``(H, W)`` arrays by dense matrix products."""
    h, w = x.shape[-2:]
    return centred_dft_matrix(h) @ x @ centred_dft_matrix(w).T


def exact_phase_history(
    amplitudes: np.ndarray, x: np.ndarray, y: np.ndarray, u: np.ndarray, theta: np.ndarray
) -> np.ndarray:
    """Deramped spotlight phase history by a triple loop over pulses, samples and scatterers.

    ``g[m, k] = sum_n a_n exp(-1j U_k (x_n cos th_m + y_n sin th_m))``.
    """
    g = np.zeros((theta.size, u.size), dtype=complex)
    for m, th in enumerate(theta):
        for k, uk in enumerate(u):
            for a, xn, yn in zip(amplitudes, x, y, strict=True):
                g[m, k] += a * np.exp(-1j * uk * (xn * math.cos(th) + yn * math.sin(th)))
    return g


def brute_force_phase(c: np.ndarray, g: np.ndarray, n: int = 3601) -> float:
    """argmin over a phase grid of ``||g - exp(1j phi) c||^2`` (c, g: 1-D complex arrays)."""
    phis = np.linspace(-math.pi, math.pi, n)
    costs = [np.sum(np.abs(g - np.exp(1j * p) * c) ** 2) for p in phis]
    return float(phis[int(np.argmin(costs))])
