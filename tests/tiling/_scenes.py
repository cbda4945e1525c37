"""Seeded synthetic scenes for the tiling tests, and slow, obvious references."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import ndimage


def scene(
    h: int,
    w: int,
    seed: int,
    *,
    seams: tuple[int, int] = (32, 32),
    n_points: int = 12,
    n_boxes: int = 10,
    big: int = 0,
) -> np.ndarray:
    """Exponential clutter (mean 1) with point targets (30-300) and speckled extended objects
    (mean 6-30; placed, not multiplied, so the dynamic range stays SAR-like), some
    planted across the seams and corners of a ``seams`` tiling and the scene border; with
    ``big`` one square object of that side straddling a corner."""
    rng = np.random.default_rng(seed)
    x = rng.exponential(size=(h, w))
    sr, sc = seams
    for _ in range(n_points):  # on seams, at corners, on the border and anywhere
        r = int(
            rng.choice(
                [rng.integers(0, h), min(h - 1, sr * rng.integers(1, h // sr + 1)), 0, h - 1]
            )
        )
        c = int(
            rng.choice(
                [rng.integers(0, w), min(w - 1, sc * rng.integers(1, w // sc + 1)), 0, w - 1]
            )
        )
        x[r, c] = rng.uniform(30, 300)
    for _ in range(n_boxes):
        bh, bw = (int(v) for v in rng.integers(3, 24, size=2))
        r = int(sr * rng.integers(1, max(2, h // sr)) - rng.integers(0, bh))
        c = int(sc * rng.integers(1, max(2, w // sc)) - rng.integers(0, bw))
        r, c = max(0, min(r, h - 1)), max(0, min(c, w - 1))
        x[r : r + bh, c : c + bw] = rng.exponential(
            size=x[r : r + bh, c : c + bw].shape
        ) * rng.uniform(6, 30)
    if big:
        r, c = max(0, sr - big // 2), max(0, sc - big // 2)
        x[r : r + big, c : c + big] = rng.exponential(size=x[r : r + big, c : c + big].shape) * 15.0
    return x.astype(np.float32)


def reference_objects(mask: np.ndarray, score: np.ndarray, connectivity: int = 2) -> pd.DataFrame:
    """Object rows of a whole mask, one component at a time (slow and plain)."""
    structure = np.ones((3, 3), bool) if connectivity == 2 else None
    lab, n = ndimage.label(mask, structure=structure)
    rows = []
    for i in range(1, n + 1):
        rr, cc = np.nonzero(lab == i)
        s = score[rr, cc].astype(np.float64)
        best = max(range(rr.size), key=lambda j: (s[j], -(rr[j] * mask.shape[1] + cc[j])))
        rows.append(
            {
                "row": rr.mean(),
                "col": cc.mean(),
                "peak_row": int(rr[best]),
                "peak_col": int(cc[best]),
                "score": s[best],
                "area": int(rr.size),
                "row_min": int(rr.min()),
                "row_max": int(rr.max()),
                "col_min": int(cc.min()),
                "col_max": int(cc.max()),
            }
        )
    rows.sort(key=lambda d: (-d["score"], d["peak_row"], d["peak_col"]))
    return pd.DataFrame(rows, columns=list(rows[0]) if rows else None)


def same_objects(got: pd.DataFrame, want: pd.DataFrame) -> None:
    """Equal object tables: integer columns exactly, centroids to float rounding."""
    assert len(got) == len(want)
    if len(want) == 0:
        return
    for col in ("peak_row", "peak_col", "area", "row_min", "row_max", "col_min", "col_max"):
        np.testing.assert_array_equal(got[col].to_numpy(), want[col].to_numpy(), err_msg=col)
    np.testing.assert_array_equal(got["score"].to_numpy(), want["score"].to_numpy())
    np.testing.assert_allclose(
        got[["row", "col"]].to_numpy(), want[["row", "col"]].to_numpy(), rtol=1e-12
    )
