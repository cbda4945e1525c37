"""Signal-to-clutter ratio (SCR) of ground-truth targets, and detections per SCR bin.

Measured SCR of a target, in dB: ``10 log10(target mean / clutter mean)`` on the image's
intensity as the data give it (before any speckle filter):

- target mean: the mean intensity over the target's instance pixels;
- clutter mean: the mean intensity over a rectangular ring around the target: the pixels
  within ``guard + width`` pixels (Chebyshev distance) of the target's bounding box but
  more than ``guard`` pixels from it (default ``guard`` :data:`SCR_GUARD` = 3, ``width``
  :data:`SCR_WIDTH` = 8: a ring 8 px wide starting 4 px outside the box), clipped to the
  image, leaving out the pixels of every target and every ignore pixel (shadows,
  don't-care regions) and non-finite samples.

The SCR is NaN (bin ``n/a``) when the ring holds no clutter pixel or both means are 0 (an
image that was not read, e.g. when scoring saved predictions); ``+inf`` when only the
clutter mean is 0. Bins (:data:`SCR_EDGES`, half-open ``[lo, hi)`` dB): ``<0``, ``0-5``,
``5-10``, ``10-15``, ``15-20``, ``>=20``, then ``n/a``.

:func:`scr_rows` counts, per source of the SCR (``measured`` on the image, ``known`` where
the data declare it, e.g. a simulator's target level over its clutter mean) and bin, the
targets and those found at an operating point (the object state keeps each target's SCR
and the score of the detection that found it, so Pd per bin is read at any operating
point).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "SCR_EDGES",
    "SCR_GUARD",
    "SCR_NAMES",
    "SCR_WIDTH",
    "scr_bins",
    "scr_rows",
    "target_scr_db",
    "wilson",
]

SCR_GUARD = 3
"""Pixels between a target's bounding box and its clutter ring."""
SCR_WIDTH = 8
"""Width in pixels of the clutter ring."""
SCR_EDGES = (0.0, 5.0, 10.0, 15.0, 20.0)
"""SCR bin edges in dB (bins ``[lo, hi)``, open at both ends)."""
SCR_NAMES = ("<0", "0-5", "5-10", "10-15", "15-20", ">=20", "n/a")
"""One name per SCR bin, then the bin of targets without an SCR."""


def target_scr_db(
    image: np.ndarray,
    ids: np.ndarray,
    ignore: np.ndarray,
    box: np.ndarray,
    plane: np.ndarray,
    *,
    guard: int = SCR_GUARD,
    width: int = SCR_WIDTH,
) -> np.ndarray:
    """Measured SCR in dB of each target (see the module docstring).

    Args:
        image: intensity ``(N, H, W)``.
        ids: int ``(N, H, W)`` instance ids ``1..G`` unique across the stack (0: none), as
            :attr:`~torchsar.metrics.matching.GroundTruth.ids`.
        ignore: bool ``(N, H, W)`` don't-care pixels (left out of the rings).
        box: ``(G, 4)`` end-exclusive boxes ``(r0, c0, r1, c1)`` (fractional boxes are
            widened to whole pixels).
        plane: int ``(G,)`` plane of each target.
        guard, width: the ring's gap to the box and its width, in pixels.

    Returns:
        float64 ``(G,)`` SCR in dB (NaN: no clutter pixel in the ring, or no signal at all).

    Examples:
        >>> img = np.ones((1, 32, 32)); img[0, 15:17, 15:17] = 100.0
        >>> ids = np.zeros((1, 32, 32), int); ids[0, 15:17, 15:17] = 1
        >>> target_scr_db(img, ids, ids < 0, np.array([[15, 15, 17, 17.]]), np.zeros(1, int))
        array([20.])
    """
    g = int(plane.shape[0])
    if g == 0:
        return np.zeros(0)
    h, w = ids.shape[-2:]
    flat = ids.reshape(-1)
    idx = np.flatnonzero(flat)
    owner = flat[idx].astype(np.int64) - 1
    values = np.asarray(image).reshape(-1)[idx].astype(np.float64)
    t_mean = np.bincount(owner, weights=values, minlength=g) / np.maximum(
        np.bincount(owner, minlength=g), 1
    )
    clutter = (ids == 0) & ~np.asarray(ignore, bool)
    b = np.asarray(box, dtype=np.float64)
    r0, c0 = np.floor(b[:, 0]).astype(np.int64), np.floor(b[:, 1]).astype(np.int64)
    r1, c1 = np.ceil(b[:, 2]).astype(np.int64), np.ceil(b[:, 3]).astype(np.int64)
    reach = guard + width
    c_mean = np.full(g, np.nan)
    for k in range(g):
        p = int(plane[k])
        R0, C0 = max(int(r0[k]) - reach, 0), max(int(c0[k]) - reach, 0)
        R1, C1 = min(int(r1[k]) + reach, h), min(int(c1[k]) + reach, w)
        sel = clutter[p, R0:R1, C0:C1].copy()
        i0, j0 = max(int(r0[k]) - guard - R0, 0), max(int(c0[k]) - guard - C0, 0)
        i1, j1 = max(int(r1[k]) + guard - R0, 0), max(int(c1[k]) + guard - C0, 0)
        sel[i0:i1, j0:j1] = False
        ring = np.asarray(image[p, R0:R1, C0:C1], dtype=np.float64)[sel]
        ring = ring[np.isfinite(ring)]
        if ring.size:
            c_mean[k] = ring.mean()
    with np.errstate(divide="ignore", invalid="ignore"):
        return 10.0 * np.log10(t_mean / c_mean)


def scr_bins(scr_db: np.ndarray, edges: tuple[float, ...] = SCR_EDGES) -> np.ndarray:
    """SCR bin index of each value: ``i`` for ``[edges[i-1], edges[i])``, ``len(edges) + 1``
    (``n/a``) for NaN.

    Examples:
        >>> scr_bins(np.array([-3.0, 0.0, 4.9, 25.0, np.inf, np.nan])).tolist()
        [0, 1, 1, 5, 5, 6]
    """
    v = np.asarray(scr_db, dtype=np.float64)
    out = np.searchsorted(np.asarray(edges, dtype=np.float64), v, side="right")
    return np.where(np.isnan(v), len(edges) + 1, out)


def wilson(k: np.ndarray, n: np.ndarray, level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """Wilson score interval of a proportion ``k / n`` (NaN where ``n == 0``); it contains
    ``k / n``, and its bound at ``k = 0`` (``k = n``) is exactly 0 (1).

    Examples:
        >>> lo, hi = wilson(np.array([0, 10]), np.array([10, 10]))
        >>> [round(float(v), 4) for v in (lo[0], hi[0], lo[1], hi[1])]
        [0.0, 0.2775, 0.7225, 1.0]
    """
    from scipy.special import ndtri

    z = float(ndtri(0.5 + level / 2))
    k, n = np.asarray(k, np.float64), np.asarray(n, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = k / n
        den = 1 + z * z / n
        mid = (p + z * z / (2 * n)) / den
        half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    # rounding leaves mid - half ~ 1e-17 at k = 0: the bounds are pinned to the point there
    lo = np.where(k <= 0, 0.0, np.clip(np.minimum(mid - half, p), 0.0, 1.0))
    hi = np.where(k >= n, 1.0, np.clip(np.maximum(mid + half, p), 0.0, 1.0))
    return np.where(n > 0, lo, np.nan), np.where(n > 0, hi, np.nan)


def scr_rows(sources: dict[str, tuple[np.ndarray, np.ndarray]], level: float = 0.95) -> list[dict]:
    """Pd per SCR bin: for each source (in the order given) ``(scr_db, found)`` of its
    targets, one row per non-empty bin with the targets, those found, Pd, its Wilson
    interval and the bin's mean finite SCR.

    Examples:
        >>> rows = scr_rows({"measured": (np.array([3.0, 4.0, 12.0]), np.array([1, 0, 1], bool))})
        >>> [(r["scr_bin"], r["targets"], r["detected"], r["scr_mean_db"]) for r in rows]
        [('0-5', 2, 1, 3.5), ('10-15', 1, 1, 12.0)]
    """
    out = []
    edges = (-math.inf, *SCR_EDGES, math.inf)
    nb = len(SCR_NAMES)
    for source, (scr_db, found) in sources.items():
        v = np.asarray(scr_db, dtype=np.float64)
        bins = scr_bins(v)
        n = np.bincount(bins, minlength=nb)
        hit = np.bincount(bins[np.asarray(found, bool)], minlength=nb)
        ok = np.isfinite(v)
        fin = np.bincount(bins[ok], minlength=nb)
        total = np.bincount(bins[ok], weights=v[ok], minlength=nb)
        lo, hi = wilson(hit, n, level)
        for b in np.flatnonzero(n):
            known = b < nb - 1
            out.append(
                {
                    "source": source,
                    "scr_bin": SCR_NAMES[b],
                    "scr_lo_db": edges[b] if known else math.nan,
                    "scr_hi_db": edges[b + 1] if known else math.nan,
                    "scr_mean_db": float(total[b] / fin[b]) if fin[b] else math.nan,
                    "targets": int(n[b]),
                    "detected": int(hit[b]),
                    "pd": float(hit[b] / n[b]),
                    "pd_lo": float(lo[b]),
                    "pd_hi": float(hi[b]),
                }
            )
    return out
