"""Threshold-free object curves from detections in rank order: COCO AP, the FROC, Pd at a
false-alarm rate and the partial AUC.

Everything here takes detections already ranked (descending score, ties in a fixed order),
as counts per detection, possibly weighted (a bootstrap replicate weights each detection by
its image's weight). A global score threshold keeps a prefix of the ranking, so the curve
points are prefixes; detections of equal score enter together (:func:`levels`). Scores
themselves never enter the arithmetic, so a strictly increasing map of the scores changes no
number.

Reading rules (stated once, used everywhere):

- FROC point of score level ``s``: the detections scoring ``>= s`` (so a threshold ``t``
  between two levels keeps those scoring ``> t``); the first point is ``(0, 0)``: nothing
  detected.
- Pd at ``k`` false alarms per image (:func:`pd_at_fa`): the FROC read as a step function
  without interpolation: the Pd of the lowest score level whose false alarms per image do not
  exceed ``k`` (0 when even the highest level exceeds it).
- Partial AUC (:func:`partial_auc`): the area under that step function over ``[0, limit]``
  false alarms per image, divided by ``limit`` (1 for a perfect detector).
- AP: COCO's 101-point interpolated precision (:func:`interpolated_precision`), one point per
  detection in rank order, as ``pycocotools`` ranks them.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "RECALL_POINTS",
    "coco_ap",
    "coco_ap_rows",
    "interpolated_precision",
    "levels",
    "partial_auc",
    "partial_auc_rows",
    "pd_at_fa",
    "pd_at_fa_rows",
]

RECALL_POINTS = np.linspace(0.0, 1.0, 101)
"""COCO's recall points (``pycocotools`` ``recThrs``)."""


def levels(score: np.ndarray) -> np.ndarray:
    """Index of the last detection of each score level of ranked ``score`` (descending).

    Examples:
        >>> levels(np.array([0.9, 0.7, 0.7, 0.2])).tolist()
        [0, 2, 3]
    """
    s = np.asarray(score)
    if s.size == 0:
        return np.zeros(0, np.int64)
    return np.flatnonzero(np.append(s[1:] != s[:-1], True))


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

    Examples:
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
    """Average precision, COCO's 101-point interpolation, of ranked detections flagged true
    positive (``tp``) or false positive (``fp``; neither: ignored). NaN without ground truth.

    Examples:
        >>> round(coco_ap(np.array([1, 0, 1]), np.array([0, 1, 0]), 2), 4)  # TP, FP, TP
        0.835
    """
    if n_gt == 0:
        return float("nan")
    return float(coco_ap_rows(np.asarray(tp)[None], np.asarray(fp)[None], np.array([n_gt]))[0])


def coco_ap_rows(tp: np.ndarray, fp: np.ndarray, n_gt: np.ndarray) -> np.ndarray:
    """COCO AP of every row of ranked, weighted detections ``(R, N)`` at once (e.g.
    bootstrap replicates: ``tp[r, i]`` the weight of detection ``i`` in replicate ``r`` when it
    is a true positive, else 0), ``n_gt`` ``(R,)``; NaN where a row has no ground truth.

    Examples:
        >>> tp = np.array([[1, 0, 1], [2, 0, 0]]); fp = np.array([[0, 1, 0], [0, 1, 0]])
        >>> np.round(coco_ap_rows(tp, fp, np.array([2, 0])), 4).tolist()
        [0.835, nan]
    """
    tp, fp = np.atleast_2d(tp), np.atleast_2d(fp)
    n_gt = np.asarray(n_gt, dtype=np.float64)
    rows = tp.shape[0]
    if rows == 0:
        return np.zeros(0)
    cols = np.flatnonzero((tp + fp).any(axis=0))  # detections that count somewhere
    if cols.size == 0:
        return np.where(n_gt > 0, 0.0, np.nan)
    tps = np.cumsum(tp[:, cols], axis=1, dtype=np.float64)
    fps = np.cumsum(fp[:, cols], axis=1, dtype=np.float64)
    recall = tps / np.where(n_gt > 0, n_gt, 1.0)[:, None]
    precision = tps / (tps + fps + np.spacing(1))
    precision = np.maximum.accumulate(precision[:, ::-1], axis=1)[:, ::-1]
    # first column reaching each recall point, row by row: exact comparisons of the recall
    # with the points, as pycocotools makes them (0.35 does not reach 0.35000000000000003)
    idx = np.stack([np.searchsorted(r, RECALL_POINTS, side="left") for r in recall])
    q = np.take_along_axis(precision, np.minimum(idx, cols.size - 1), axis=1)
    q = np.where(idx < cols.size, q, 0.0)
    return np.where(n_gt > 0, q.mean(axis=1), np.nan)


def pd_at_fa(fa: np.ndarray, pd: np.ndarray, level: float) -> float:
    """Pd at ``level`` false alarms per image from FROC points (``fa`` non-decreasing, the
    first point ``(0, 0)``): the last point with ``fa <= level`` (see the module docstring).

    Examples:
        >>> pd_at_fa(np.array([0.0, 0.5, 2.0]), np.array([0.0, 0.4, 0.8]), 1.0)
        0.4
    """
    return float(pd_at_fa_rows(np.asarray(fa)[None], np.asarray(pd)[None], level)[0])


def pd_at_fa_rows(fa: np.ndarray, pd: np.ndarray, level: float) -> np.ndarray:
    """:func:`pd_at_fa` of every row of FROC points ``(R, K)`` (each row's ``fa``
    non-decreasing; Pd non-decreasing too, so the last point within the level is the best)."""
    fa, pd = np.atleast_2d(fa), np.atleast_2d(pd)
    if fa.shape[1] == 0:
        return np.zeros(fa.shape[0])
    last = (fa <= level).sum(axis=1) - 1
    return np.where(last >= 0, np.take_along_axis(pd, np.maximum(last, 0)[:, None], 1)[:, 0], 0.0)


def partial_auc(fa: np.ndarray, pd: np.ndarray, limit: float = 1.0) -> float:
    """Mean Pd over false alarms per image in ``[0, limit]`` (see the module docstring).

    Examples:
        >>> partial_auc(np.array([0.0, 0.5, 2.0]), np.array([0.0, 0.4, 0.8]))
        0.2
    """
    return float(partial_auc_rows(np.asarray(fa)[None], np.asarray(pd)[None], limit)[0])


def partial_auc_rows(fa: np.ndarray, pd: np.ndarray, limit: float = 1.0) -> np.ndarray:
    """:func:`partial_auc` of every row of FROC points ``(R, K)`` at once (each row's false
    alarms non-decreasing from its first point, e.g. bootstrap replicates).

    Examples:
        >>> fa = np.array([[0.0, 0.5, 2.0]]); pd = np.array([[0.0, 0.4, 0.8]])
        >>> partial_auc_rows(fa, pd).tolist() == [partial_auc(fa[0], pd[0])]
        True
    """
    fa, pd = np.atleast_2d(fa), np.atleast_2d(pd)
    end = np.minimum(np.hstack([fa[:, 1:], np.full((fa.shape[0], 1), limit)]), limit)
    width = np.where(fa < limit, np.maximum(end - fa, 0.0), 0.0)
    return np.nansum(pd * width, axis=1) / limit
