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

:class:`ScrCounts` keeps, per source of the SCR (``measured`` on the image, ``known``
where the data declare it, e.g. a simulator's target level over its clutter mean) and bin,
the targets and the score histogram of the detections that matched them, so Pd per bin is
read at any operating point and the state adds up across batches, shards and workers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from torchsar.metrics.curves import SCORE_GRID

__all__ = [
    "SCR_EDGES",
    "SCR_GUARD",
    "SCR_NAMES",
    "SCR_WIDTH",
    "ScrCounts",
    "scr_bins",
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

_N_SCORE_BINS = SCORE_GRID.size + 1
DB_UNIT = 10**6
"""SCRs are summed as integers in units of 1e-6 dB, so sums are exact in any order."""


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

    Example:
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
        np.bincount(owner, minlength=g), 1)  # fmt: skip
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

    Example:
        >>> scr_bins(np.array([-3.0, 0.0, 4.9, 25.0, np.inf, np.nan])).tolist()
        [0, 1, 1, 5, 5, 6]
    """
    v = np.asarray(scr_db, dtype=np.float64)
    out = np.searchsorted(np.asarray(edges, dtype=np.float64), v, side="right")
    return np.where(np.isnan(v), len(edges) + 1, out)


def wilson(k: np.ndarray, n: np.ndarray, level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """Wilson score interval of a proportion ``k / n`` (NaN where ``n == 0``); it contains
    ``k / n``, and its bound at ``k = 0`` (``k = n``) is exactly 0 (1).

    Example:
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


def _zeros(*shape: int) -> np.ndarray:
    return np.zeros(shape, np.int64)


@dataclass(eq=False)
class ScrCounts:
    """Targets per SCR source and bin, and the score bins of the detections that found
    them (additive; see the module docstring).

    Attributes:
        n: ``{source: (bins,)}`` targets.
        tp: ``{source: (bins, score bins)}`` targets by the score bin of the detection that
            matched them under the matching rule (found at operating point ``at``:
            ``tp[:, at:].sum(1)``).
        db: ``{source: (bins,)}`` sum of the finite SCRs in units of :data:`DB_UNIT`.
        finite: ``{source: (bins,)}`` targets with a finite SCR.
    """

    n: dict[str, np.ndarray] = field(default_factory=dict)
    tp: dict[str, np.ndarray] = field(default_factory=dict)
    db: dict[str, np.ndarray] = field(default_factory=dict)
    finite: dict[str, np.ndarray] = field(default_factory=dict)

    def update(self, source: str, scr_db: np.ndarray, found_bin: np.ndarray) -> None:
        """Add targets of SCR ``scr_db`` whose detection has score bin ``found_bin`` (-1:
        missed)."""
        nb = len(SCR_NAMES)
        if source not in self.n:
            for part in (self.n, self.db, self.finite):
                part[source] = _zeros(nb)
            self.tp[source] = _zeros(nb, _N_SCORE_BINS)
        v = np.asarray(scr_db, dtype=np.float64)
        bins = scr_bins(v)
        self.n[source] += np.bincount(bins, minlength=nb)
        hit = found_bin >= 0
        np.add.at(self.tp[source], (bins[hit], found_bin[hit]), 1)
        ok = np.isfinite(v)
        units = np.rint(v[ok] * DB_UNIT).astype(np.int64)
        self.db[source] += _sum_by(bins[ok], units, nb)
        self.finite[source] += np.bincount(bins[ok], minlength=nb)

    def __add__(self, other: ScrCounts) -> ScrCounts:
        out = ScrCounts()
        for name in ("n", "tp", "db", "finite"):
            mine, theirs = getattr(self, name), getattr(other, name)
            merged = {k: v.copy() for k, v in mine.items()}
            for k, v in theirs.items():
                merged[k] = merged[k] + v if k in merged else v.copy()
            setattr(out, name, merged)
        return out

    def rows(self, at: int, level: float = 0.95) -> list[dict]:
        """Per source and non-empty bin: targets, found at score bin ``at`` and above, Pd,
        its Wilson interval and the bin's mean finite SCR."""
        out = []
        edges = (-math.inf, *SCR_EDGES, math.inf)
        for source in sorted(self.n, key=lambda s: (s != "measured", s)):
            n = self.n[source]
            found = self.tp[source][:, at:].sum(axis=1)
            lo, hi = wilson(found, n, level)
            for b in np.flatnonzero(n):
                known = b < len(SCR_NAMES) - 1
                fin = self.finite[source][b]
                out.append({
                    "source": source,
                    "scr_bin": SCR_NAMES[b],
                    "scr_lo_db": edges[b] if known else math.nan,
                    "scr_hi_db": edges[b + 1] if known else math.nan,
                    "scr_mean_db": self.db[source][b] / DB_UNIT / fin if fin else math.nan,
                    "targets": int(n[b]),
                    "detected": int(found[b]),
                    "pd": float(found[b] / n[b]),
                    "pd_lo": float(lo[b]),
                    "pd_hi": float(hi[b]),
                })  # fmt: skip
        return out


def _sum_by(bins: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Exact integer sums of ``values`` per bin."""
    out = np.zeros(n, np.int64)
    np.add.at(out, bins, values)
    return out
