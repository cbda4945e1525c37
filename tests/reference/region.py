"""A slow, obvious region-growing CFAR (seed section 3, steps a–j) for tests.

Pure Python/numpy loops: the boundary is rescanned at every step, rings are found by
checking the Chebyshev distance of every pixel to the region. Only for tiny images.
"""

from __future__ import annotations

import numpy as np


def _neighbours(p: int, h: int, w: int, connectivity: int) -> list[int]:
    r, c = divmod(p, w)
    steps = [(-1, 0), (1, 0), (0, -1), (0, 1)]
    if connectivity == 8:
        steps += [(-1, -1), (-1, 1), (1, -1), (1, 1)]
    return [(r + dr) * w + c + dc for dr, dc in steps if 0 <= r + dr < h and 0 <= c + dc < w]


def seeds(f: np.ndarray, window: int = 5) -> list[int]:
    """Local maxima of ``f`` over ``window x window``, brightest first, ties by index."""
    h, w = f.shape
    r = window // 2
    out = [
        i * w + j
        for i in range(h)
        for j in range(w)
        if f[i, j] == f[max(i - r, 0) : i + r + 1, max(j - r, 0) : j + r + 1].max()
    ]
    return sorted(out, key=lambda p: (-f.flat[p], p))


def grow(
    f: np.ndarray, seed: int, free: np.ndarray, tau: float, n_init: int, connectivity: int = 4
) -> list[int]:
    """Add the most similar boundary pixel while ``|F - mu| <= tau * max(F over T)``."""
    h, w = f.shape
    flat = f.reshape(-1)
    region = [seed]
    mu_n = None
    while True:
        inside = set(region)
        boundary = {
            q
            for p in region
            for q in _neighbours(p, h, w, connectivity)
            if q not in inside and free[q]
        }
        if not boundary:
            return region
        mu = np.mean(flat[region]) if mu_n is None else mu_n
        beta = flat[region].max()
        p = min(boundary, key=lambda q: (abs(flat[q] - mu), q))
        if abs(flat[p] - mu) > tau * beta:
            return region
        region.append(p)
        if mu_n is None and len(region) == n_init:
            mu_n = np.mean(flat[region])


def rings(region: list[int], shape: tuple[int, int], guard: int, background: int):
    """Guard area K and background ring C by Chebyshev distance to the region."""
    h, w = shape
    rr = np.array([p // w for p in region])
    cc = np.array([p % w for p in region])
    ii, jj = np.mgrid[:h, :w]
    d = np.full(shape, np.inf)
    for r, c in zip(rr, cc, strict=True):
        d = np.minimum(d, np.maximum(abs(ii - r), abs(jj - c)))
    return d <= guard, (d > guard) & (d <= guard + background)


def region_cfar(
    raw: np.ndarray,
    f: np.ndarray,
    *,
    tau: float = 0.3,
    n_init: int = 4,
    guard: int = 3,
    background: int = 3,
    k: float = 0.25,
    min_background: int = 15,
    lowpass: np.ndarray | None = None,
    target_on: str = "raw",
    connectivity: int = 4,
    blocking: str = "all",
) -> tuple[np.ndarray, list[dict]]:
    """The painted statistic (max over overlapping regions) and one dict per region."""
    h, w = raw.shape
    low = f if lowpass is None else lowpass
    tgt = raw if target_on == "raw" else f
    free = np.ones(h * w, bool)
    covered = np.zeros(h * w, bool)
    taken = np.zeros((h, w), bool)
    stat = np.full(h * w, -np.inf)
    rows = []
    for s in seeds(f):
        if covered[s]:
            continue
        region = grow(f, s, free, tau, n_init, connectivity)
        covered[region] = True
        if blocking == "all":
            free[region] = False
        mu_t = tgt.reshape(-1)[region].mean()
        _, c = rings(region, (h, w), guard, background)
        c &= (low < mu_t) & ~taken
        z, ok = -np.inf, False
        if c.sum() >= min_background:
            mu_c, sd = raw[c].mean(), raw[c].std()
            z = (mu_t - mu_c) / sd
            ok = z > k
        if ok:
            taken.reshape(-1)[region] = True
            free[region] = False
        stat[region] = np.maximum(stat[region], z)
        rows.append({"seed": s, "region": sorted(region), "statistic": z, "accepted": ok})
    return stat.reshape(h, w), rows


def fill_holes(stat: np.ndarray, region_id: np.ndarray, k: float, statistic_of) -> tuple:
    """Holes of ``stat > k`` (scipy's binary_fill_holes) given, per hole, the largest
    accepted id among the 8-neighbours of its pixels: returns new ``(stat, region_id)``."""
    from scipy import ndimage

    h, w = stat.shape
    mask = stat > k
    holes = ndimage.binary_fill_holes(mask) & ~mask
    lab, n = ndimage.label(holes)
    stat, region_id = stat.copy(), region_id.copy()
    for i in range(1, n + 1):
        owner = 0
        for r, c in zip(*np.nonzero(lab == i), strict=True):
            for rr in range(max(r - 1, 0), min(r + 2, h)):
                for cc in range(max(c - 1, 0), min(c + 2, w)):
                    if mask[rr, cc]:
                        owner = max(owner, int(region_id[rr, cc]))
        region_id[lab == i] = owner
        stat[lab == i] = statistic_of(owner)
    return stat, region_id


def small_objects(mask: np.ndarray, min_size: int) -> np.ndarray:
    """Pixels of the 8-connected components of ``mask`` with fewer than ``min_size`` pixels."""
    from scipy import ndimage

    lab, n = ndimage.label(mask, structure=np.ones((3, 3), dtype=bool))
    out = np.zeros_like(mask)
    for i in range(1, n + 1):
        if (lab == i).sum() < min_size:
            out |= lab == i
    return out


def merged_labels(mask: np.ndarray, merge: int) -> np.ndarray:
    """One label per group of ``mask`` pixels closer than ``merge`` (0: 8-connected), numbered
    in raster order of each group's first pixel, over the whole image."""
    from scipy import ndimage

    grown = ndimage.binary_dilation(mask, np.ones((2 * merge + 1,) * 2)) if merge else mask
    lab, _ = ndimage.label(grown, structure=np.ones((3, 3), dtype=bool))
    return np.where(mask, lab, 0)
