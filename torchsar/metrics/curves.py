"""Threshold-free object metrics from score histograms: COCO AP, FROC, Pd at fixed false
alarms per image, partial AUC.

Histograms count detections per score bin of a fixed grid (bin ``b`` holds scores in
``(grid[b-1], grid[b]]``); the curves visit bins from the highest score down, so each point is
"every detection scoring above this level", exactly what a global threshold on the score gives.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "OP_BIN",
    "SCORE_GRID",
    "coco_ap",
    "coco_ap_rows",
    "froc",
    "interpolated_precision",
    "partial_auc",
    "partial_auc_rows",
    "pd_at_fa",
    "score_bins",
    "suffix",
]

SCORE_GRID = np.concatenate(
    [-(10.0 ** (np.arange(150, -301, -1) / 50.0)), [0.0], 10.0 ** (np.arange(-300, 301) / 50.0)]
)
"""Score bin edges, 50 per decade on each side of 0: -1e3 .. -1e-6, 0, 1e-6 .. 1e6 (1.0 is
an edge exactly). Scores normalised by the operating threshold (a CFAR's statistic over
its design threshold, a probability over a declared threshold) put the operating point at
1; raw scores of any range (probabilities, logits) still fall on the grid."""

OP_BIN = int(np.searchsorted(SCORE_GRID, 1.0)) + 1
"""First bin of scores > 1: the design operating point."""

RECALL_POINTS = np.linspace(0.0, 1.0, 101)
"""COCO's recall points (``pycocotools`` ``recThrs``)."""


def score_bins(score: np.ndarray) -> np.ndarray:
    """Bin index of each score: ``grid[b-1] < score <= grid[b]`` (0 below the grid,
    ``len(grid)`` above it)."""
    return np.searchsorted(SCORE_GRID, np.asarray(score, dtype=np.float64), side="left")


def suffix(hist: np.ndarray) -> np.ndarray:
    """``out[..., j] = hist[..., j:].sum()``: counts scoring above ``grid[j - 1]``."""
    return np.flip(np.cumsum(np.flip(hist, -1), -1), -1)


def interpolated_precision(
    tp_cum: np.ndarray, fp_cum: np.ndarray, n_gt: int
) -> tuple[np.ndarray, float]:
    """COCO's interpolated precision at the 101 recall points and the final recall, from
    cumulative true / false positive counts of the detections in ranked order (an ignored
    detection repeats the previous counts), exactly as ``pycocotools``' ``accumulate``.

    Args:
        tp_cum, fp_cum: ``(N,)`` cumulative counts after each ranked detection.
        n_gt: ground-truth instances (> 0).

    Returns:
        ``(precision (101,), recall)``; precision is 0 at recall points never reached.

    Example:
        >>> p, r = interpolated_precision(np.array([1, 1, 2]), np.array([0, 1, 1]), 2)
        >>> round(float(p.mean()), 4), r  # precision 1 up to recall 0.5, then 2/3
        (0.835, 1.0)
    """
    tps = np.asarray(tp_cum, dtype=np.float64)
    if tps.size == 0:
        return np.zeros(RECALL_POINTS.size), 0.0
    recall = tps / n_gt
    precision = tps / (tps + np.asarray(fp_cum, dtype=np.float64) + np.spacing(1))
    precision = np.maximum.accumulate(precision[::-1])[::-1]
    idx = np.searchsorted(recall, RECALL_POINTS, side="left")
    q = np.where(idx < precision.size, precision[np.minimum(idx, precision.size - 1)], 0.0)
    return q, float(recall[-1])


def coco_ap(tp: np.ndarray, fp: np.ndarray, n_gt: int) -> float:
    """Average precision, COCO's 101-point interpolation, from TP / FP score histograms.

    Equals ``pycocotools`` exactly when no score bin mixes true and false positives (e.g.
    every score on a distinct grid point); within a mixed bin the detections count as tied.
    NaN when there is no ground truth.

    Example:
        >>> tp = np.zeros(352, int); fp = np.zeros(352, int)
        >>> tp[300] = 1; fp[200] = 1; tp[100] = 1  # ranked TP, FP, TP
        >>> round(coco_ap(tp, fp, 2), 4)  # precision 1 up to recall 0.5, then 2/3
        0.835
    """
    if n_gt == 0:
        return float("nan")
    rev = np.flatnonzero((np.asarray(tp) + np.asarray(fp))[::-1] > 0)
    tps = np.cumsum(np.asarray(tp)[::-1], dtype=np.float64)[rev]
    fps = np.cumsum(np.asarray(fp)[::-1], dtype=np.float64)[rev]
    return float(interpolated_precision(tps, fps, n_gt)[0].mean())


def coco_ap_rows(tp: np.ndarray, fp: np.ndarray, n_gt: np.ndarray) -> np.ndarray:
    """:func:`coco_ap` of every row of TP / FP histograms ``(R, N)`` at once (e.g. bootstrap
    replicates, ``n_gt`` ``(R,)``); NaN where a row has no ground truth.

    Example:
        >>> tp = np.zeros((2, 352), int); fp = np.zeros_like(tp)
        >>> tp[:, 300] = 1; fp[:, 200] = 1; tp[:, 100] = 1
        >>> np.round(coco_ap_rows(tp, fp, np.array([2, 0])), 4).tolist()
        [0.835, nan]
    """
    tp, fp = np.atleast_2d(tp), np.atleast_2d(fp)
    n_gt = np.asarray(n_gt, dtype=np.float64)
    rows = tp.shape[0]
    if rows == 0:
        return np.zeros(0)
    cols = np.flatnonzero((tp + fp).any(axis=0))[::-1]  # bins holding detections, best first
    if cols.size == 0:
        return np.where(n_gt > 0, 0.0, np.nan)
    tps = np.cumsum(tp[:, cols], axis=1, dtype=np.float64)
    fps = np.cumsum(fp[:, cols], axis=1, dtype=np.float64)
    recall = tps / np.where(n_gt > 0, n_gt, 1.0)[:, None]
    precision = tps / (tps + fps + np.spacing(1))
    precision = np.maximum.accumulate(precision[:, ::-1], axis=1)[:, ::-1]
    # first column reaching each recall point, per row: one search over rows laid end to end
    offset = (float(recall.max()) + 2.0) * np.arange(rows)[:, None]
    idx = np.searchsorted((recall + offset).reshape(-1), (RECALL_POINTS + offset).reshape(-1))
    idx = idx.reshape(rows, -1) - cols.size * np.arange(rows)[:, None]
    q = np.take_along_axis(precision, np.minimum(idx, cols.size - 1), axis=1)
    q = np.where(idx < cols.size, q, 0.0)
    return np.where(n_gt > 0, q.mean(axis=1), np.nan)


def froc(tp: np.ndarray, fp: np.ndarray, n_gt: int, images: int) -> tuple[np.ndarray, ...]:
    """FROC points at every grid level, highest score first: false alarms per image and Pd
    (both monotone non-decreasing), starting at ``(0, 0)`` (nothing detected)."""
    ct, cf = suffix(np.asarray(tp))[::-1], suffix(np.asarray(fp))[::-1]
    fa = np.concatenate([[0.0], cf / max(images, 1)])
    pd = np.concatenate([[0.0], ct / n_gt if n_gt else np.full(ct.shape, np.nan)])
    return fa, pd


def pd_at_fa(fa: np.ndarray, pd: np.ndarray, level: float) -> float:
    """Best Pd with at most ``level`` false alarms per image (the FROC read at ``level``;
    beyond the curve's last point the detector's final Pd holds)."""
    ok = fa <= level
    return float(pd[ok].max()) if ok.any() else 0.0


def partial_auc(fa: np.ndarray, pd: np.ndarray, limit: float = 1.0) -> float:
    """Mean Pd over false alarms per image in ``[0, limit]`` (area under the step FROC,
    normalised to 1 for a perfect detector)."""
    xs = np.concatenate([fa[fa < limit], [limit]])
    held = np.array([pd_at_fa(fa, pd, x) for x in xs[:-1]])
    return float(np.sum(held * np.diff(xs)) / limit) if xs.size > 1 else 0.0


def partial_auc_rows(fa: np.ndarray, pd: np.ndarray, limit: float = 1.0) -> np.ndarray:
    """:func:`partial_auc` of every row of FROC points ``(R, K)`` at once (each row's false
    alarms non-decreasing from its first point, e.g. bootstrap replicates).

    Example:
        >>> fa = np.array([[0.0, 0.5, 2.0]]); pd = np.array([[0.0, 0.4, 0.8]])
        >>> partial_auc_rows(fa, pd).tolist() == [partial_auc(fa[0], pd[0])]
        True
    """
    fa, pd = np.atleast_2d(fa), np.atleast_2d(pd)
    end = np.minimum(np.hstack([fa[:, 1:], np.full((fa.shape[0], 1), limit)]), limit)
    width = np.where(fa < limit, np.maximum(end - fa, 0.0), 0.0)
    return np.nansum(pd * width, axis=1) / limit
