"""Steps e–h: guard ring K and background ring C of a region, censoring, ring statistics.

All on a crop: the region's bounding box widened by ``guard + background`` (clipped to the
image), never the whole image per region. Dilation uses a square structuring element
(Chebyshev distance), the region analogue of the square guard box of window CFARs;
dilating by ``guard`` then by ``background`` equals one dilation by their sum.

This runs once per grown region inside the CPU loop, so it works on numpy views with few
array operations: a square dilation is "the box sum of the mask is positive", read off one
summed-area table (integer counts, exact) that serves both K and the outer edge of C.
The ring statistics use the same reductions as ``ndarray.mean`` / ``ndarray.std``, without
their per-call overhead, so the numbers are the same to the bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from torchsar.region.boxes import index_box

__all__ = [
    "Crop",
    "RingStats",
    "crop_around",
    "dilate",
    "mean_std",
    "ring_masks",
    "ring_stats",
]


@dataclass(frozen=True)
class Crop:
    """A rectangle ``[r0, r1) x [c0, c1)`` of an image and a region's mask inside it."""

    r0: int
    r1: int
    c0: int
    c1: int
    region: np.ndarray  # bool (r1 - r0, c1 - c0)

    def cut(self, img: np.ndarray) -> np.ndarray:
        """The same rectangle of an ``(H, W)`` array (a view)."""
        return img[self.r0 : self.r1, self.c0 : self.c1]


def crop_around(idx: np.ndarray, shape: tuple[int, int], margin: int) -> Crop:
    """The bounding box of flat indices ``idx`` widened by ``margin``, clipped to ``shape``.

    Examples:
        >>> c = crop_around(np.array([5]), (4, 4), 1)
        >>> (c.r0, c.r1, c.c0, c.c1), c.region.sum().item()
        ((0, 3, 0, 3), 1)
    """
    r0, r1, c0, c1 = index_box(idx, shape, margin)
    rows, cols = np.divmod(idx, shape[1])
    mask = np.zeros((r1 - r0, c1 - c0), dtype=bool)
    mask[rows - r0, cols - c0] = True
    return Crop(r0, r1, c0, c1, mask)


def _summed_area(mask: np.ndarray, pad: int) -> np.ndarray:
    """The summed-area table of a bool ``(h, w)`` mask zero-padded by ``pad`` on every side:
    ``S[a, b]`` = number of set cells of the padded mask above and left of ``(a, b)``;
    shape ``(h + 2 pad + 1, w + 2 pad + 1)``, integer (exact counts)."""
    h, w = mask.shape
    n = h + 2 * pad + 1, w + 2 * pad + 1
    s = np.zeros(n, dtype=np.int32 if n[0] * n[1] < 2**30 else np.int64)  # sums of two fit
    s[pad + 1 : pad + 1 + h, pad + 1 : pad + 1 + w] = mask
    s.cumsum(axis=0, out=s)
    s.cumsum(axis=1, out=s)
    return s


def _box_any(s: np.ndarray, pad: int, radius: int, shape: tuple[int, int]) -> np.ndarray:
    """Cells of the unpadded ``shape`` whose ``(2 radius + 1)^2`` box holds a set cell, from
    a :func:`_summed_area` table padded by ``pad >= radius``."""
    h, w = shape
    lo, hi = pad - radius, pad + radius + 1
    inside = s[hi : hi + h, hi : hi + w] + s[lo : lo + h, lo : lo + w]
    return inside > s[lo : lo + h, hi : hi + w] + s[hi : hi + h, lo : lo + w]  # count > 0


def dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """Dilate a bool ``(h, w)`` mask by a ``(2 radius + 1)^2`` square (outside = False).

    Examples:
        >>> m = np.zeros((5, 5), dtype=bool); m[2, 2] = True
        >>> int(dilate(m, 1).sum())
        9
    """
    return _box_any(_summed_area(mask, radius), radius, radius, mask.shape)


def ring_masks(region: np.ndarray, guard: int, background: int) -> tuple[np.ndarray, np.ndarray]:
    """Guard area K (region dilated by ``guard``, region included) and background ring C
    (K dilated by ``background``, minus K) — seed steps e and f.

    Examples:
        >>> t = np.zeros((9, 9), dtype=bool); t[4, 4] = True
        >>> k, c = ring_masks(t, 1, 2)
        >>> int(k.sum()), int(c.sum())
        (9, 40)
    """
    pad = guard + background  # square dilations compose: g then b = g + b
    s = _summed_area(region, pad)
    k = _box_any(s, pad, guard, region.shape)
    c = _box_any(s, pad, pad, region.shape)
    np.greater(c, k, out=c)  # c and not k
    return k, c


def mean_std(v: np.ndarray) -> tuple[float, float]:
    """``(v.mean(), v.std())`` of a non-empty 1-D float64 array, computed as numpy computes
    them (the same pairwise sums and divisions, so equal to the bit) with one shared sum.

    Examples:
        >>> mean_std(np.array([1.0, 2.0, 4.0, 5.0]))
        (3.0, 1.5811388300841898)
    """
    n = v.size
    mu = np.add.reduce(v) / n
    d = v - mu
    np.square(d, out=d)
    return float(mu), math.sqrt(np.add.reduce(d) / n)


@dataclass(frozen=True)
class RingStats:
    """Statistics of one region: ``mu_t`` (step d), the censored background size and
    ``mu_c`` / ``sigma_c`` (step h, population standard deviation)."""

    mu_t: float
    n_background: int
    mu_c: float
    sigma_c: float


def ring_stats(
    crop: Crop,
    raw: np.ndarray,
    target_img: np.ndarray,
    lowpass: np.ndarray,
    taken: np.ndarray,
    guard: int,
    background: int,
) -> RingStats:
    """Steps d–h on one crop.

    ``mu_t`` is the mean of ``target_img`` over the region. The background ring C loses the
    pixels whose low-pass value is ``>= mu_t`` and the pixels in ``taken`` (already detected
    targets); ``mu_c`` and ``sigma_c`` are taken from ``raw`` over what remains.

    Args:
        crop: the region and its crop rectangle.
        raw, target_img, lowpass, taken: full ``(H, W)`` CPU arrays (``taken`` bool).
        guard, background: ring widths R_G and R_C.
    """
    _, ring = ring_masks(crop.region, guard, background)
    t = crop.cut(target_img)[crop.region]
    mu_t = float(np.add.reduce(t) / t.size)
    ring &= crop.cut(lowpass) < mu_t
    np.greater(ring, crop.cut(taken), out=ring)  # ring and not taken
    vals = crop.cut(raw)[ring]
    if vals.size == 0:
        return RingStats(mu_t, 0, float("nan"), float("nan"))
    mu_c, sigma_c = mean_std(vals)
    return RingStats(mu_t, int(vals.size), mu_c, sigma_c)
