"""Slow, obvious speckle filters: a per-pixel loop over the window, the textbook formulas.

Border rule (the library's): statistics and weighted means over the window cells inside the
image. Works on one 2-D float64 numpy plane at a time.
"""

from __future__ import annotations

import math

import numpy as np


def window(img: np.ndarray, i: int, j: int, r: int) -> tuple[np.ndarray, np.ndarray]:
    """In-image cells of the window around (i, j) and their distances to (i, j)."""
    vals, dists = [], []
    for di in range(-r, r + 1):
        for dj in range(-r, r + 1):
            a, b = i + di, j + dj
            if 0 <= a < img.shape[0] and 0 <= b < img.shape[1]:
                vals.append(img[a, b])
                dists.append(math.sqrt(di * di + dj * dj))
    return np.array(vals), np.array(dists)


def stats(vals: np.ndarray) -> tuple[float, float]:
    """Window mean and Ci = population std / mean (0 for a zero mean)."""
    mu = vals.mean()
    sigma = math.sqrt(((vals - mu) ** 2).mean())
    return mu, (sigma / mu if mu > 0 else 0.0)


def lee_pixel(obs, mu, ci, vals, dists, L, K):
    cu = 1 / math.sqrt(L)
    w = 0.0 if ci == 0 else min(max(1 - cu**2 / ci**2, 0.0), 1.0)
    return mu + w * (obs - mu)


def kuan_pixel(obs, mu, ci, vals, dists, L, K):
    cu = 1 / math.sqrt(L)
    w = 0.0 if ci == 0 else min(max((1 - cu**2 / ci**2) / (1 + cu**2), 0.0), 1.0)
    return mu + w * (obs - mu)


def three_classes(obs, mu, ci, L, textured):
    """The enhanced filters' classes: homogeneous (Ci <= Cu) -> mu, point (Ci >= Cmax) ->
    obs, textured -> ``textured(cu, cmax)``."""
    cu, cmax = 1 / math.sqrt(L), math.sqrt(1 + 2 / L)
    if ci <= cu:
        return mu
    if ci >= cmax:
        return obs
    return textured(cu, cmax)


def enhanced_lee_pixel(obs, mu, ci, vals, dists, L, K):
    def textured(cu, cmax):
        w = math.exp(-K * (ci - cu) / (cmax - ci))
        return mu * w + obs * (1 - w)

    return three_classes(obs, mu, ci, L, textured)


def weighted_mean(vals, dists, a):
    w = np.exp(-a * dists)
    return float((w * vals).sum() / w.sum())


def frost_pixel(obs, mu, ci, vals, dists, L, K):
    return weighted_mean(vals, dists, K * ci**2)


def enhanced_frost_pixel(obs, mu, ci, vals, dists, L, K):
    def textured(cu, cmax):
        return weighted_mean(vals, dists, K * (ci - cu) / (cmax - ci))

    return three_classes(obs, mu, ci, L, textured)


def gamma_map_pixel(obs, mu, ci, vals, dists, L, K):
    def textured(cu, cmax):
        a = (1 + cu**2) / (ci**2 - cu**2)
        b = a - L - 1
        return (b * mu + math.sqrt(b * b * mu * mu + 4 * a * L * mu * obs)) / (2 * a)

    return three_classes(obs, mu, ci, L, textured)


PIXEL = {
    "lee": lee_pixel,
    "kuan": kuan_pixel,
    "enhanced_lee": enhanced_lee_pixel,
    "frost": frost_pixel,
    "enhanced_frost": enhanced_frost_pixel,
    "gamma_map": gamma_map_pixel,
}


def reference(name: str, img: np.ndarray, window_size: int, looks: float, damping: float):
    """Filter one 2-D plane with the named filter, pixel by pixel."""
    r = window_size // 2
    out = np.empty_like(img, dtype=np.float64)
    for i in range(img.shape[0]):
        for j in range(img.shape[1]):
            vals, dists = window(img, i, j, r)
            mu, ci = stats(vals)
            out[i, j] = PIXEL[name](img[i, j], mu, ci, vals, dists, looks, damping)
    return out


def reference_batch(name: str, x, window_size: int, looks: float, damping: float) -> np.ndarray:
    """``reference`` on every ``(b, c)`` plane of a ``(B, C, H, W)`` array or tensor."""
    a = np.asarray(x, dtype=np.float64)
    out = np.empty_like(a)
    for b in range(a.shape[0]):
        for c in range(a.shape[1]):
            out[b, c] = reference(name, a[b, c], window_size, looks, damping)
    return out
