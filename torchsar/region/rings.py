"""Steps e–h: guard ring K and background ring C of a region, censoring, ring statistics.

All on a crop: the region's bounding box widened by ``guard + background`` (clipped to the
image), never the whole image per region. Dilation uses a square structuring element
(Chebyshev distance), the region analogue of the square guard box of window CFARs;
dilating by ``guard`` then by ``background`` equals one dilation by their sum.

This runs once per grown region inside the CPU loop, so it works on numpy views and uses
:func:`scipy.ndimage.maximum_filter` (exact, separable): on such small crops its per-call
cost is far below that of ``torch.nn.functional.max_pool2d``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

__all__ = ["Crop", "RingStats", "crop_around", "dilate", "ring_masks", "ring_stats"]


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

    Example:
        >>> c = crop_around(np.array([5]), (4, 4), 1)
        >>> (c.r0, c.r1, c.c0, c.c1), c.region.sum().item()
        ((0, 3, 0, 3), 1)
    """
    h, w = shape
    rows, cols = idx // w, idx % w
    r0, r1 = max(int(rows.min()) - margin, 0), min(int(rows.max()) + margin + 1, h)
    c0, c1 = max(int(cols.min()) - margin, 0), min(int(cols.max()) + margin + 1, w)
    mask = np.zeros((r1 - r0, c1 - c0), dtype=bool)
    mask[rows - r0, cols - c0] = True
    return Crop(r0, r1, c0, c1, mask)


def dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """Dilate a bool ``(h, w)`` mask by a ``(2 radius + 1)^2`` square (outside = False).

    Example:
        >>> m = np.zeros((5, 5), dtype=bool); m[2, 2] = True
        >>> int(dilate(m, 1).sum())
        9
    """
    if radius == 0:
        return mask.copy()
    return ndimage.maximum_filter(mask, size=2 * radius + 1, mode="constant", cval=False)


def ring_masks(region: np.ndarray, guard: int, background: int) -> tuple[np.ndarray, np.ndarray]:
    """Guard area K (region dilated by ``guard``, region included) and background ring C
    (K dilated by ``background``, minus K) — seed steps e and f.

    Example:
        >>> t = np.zeros((9, 9), dtype=bool); t[4, 4] = True
        >>> k, c = ring_masks(t, 1, 2)
        >>> int(k.sum()), int(c.sum())
        (9, 40)
    """
    k = dilate(region, guard)
    c = dilate(region, guard + background) & ~k  # square dilations compose: g then b = g + b
    return k, c


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
    region = crop.region
    mu_t = float(crop.cut(target_img)[region].mean())
    ring &= crop.cut(lowpass) < mu_t
    ring &= ~crop.cut(taken)
    vals = crop.cut(raw)[ring]
    if vals.size == 0:
        return RingStats(mu_t, 0, float("nan"), float("nan"))
    return RingStats(mu_t, int(vals.size), float(vals.mean()), float(vals.std()))
