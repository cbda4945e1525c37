"""Slow, obvious references for distance matching: every partial one-to-one matching
enumerated, the greedy visit as a plain loop, and the xView3-SAR scoring steps written out
(DIUx-xView/xview3-reference, reference/metric.py, with ``costly_dist``)."""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment


def brute_force_optimal(dist: np.ndarray, tol: float) -> tuple[int, float]:
    """Try every partial one-to-one matching whose pairs are all closer than ``tol``; return
    the largest number of pairs and, among matchings with that many, the least total
    distance."""
    n_det, n_gt = dist.shape
    best = (0, 0.0)

    def visit(i: int, used: frozenset, pairs: int, total: float) -> None:
        nonlocal best
        if i == n_det:
            if pairs > best[0] or (pairs == best[0] and total < best[1]):
                best = (pairs, total)
            return
        visit(i + 1, used, pairs, total)  # detection i left unmatched
        for j in range(n_gt):
            if j not in used and dist[i, j] < tol:
                visit(i + 1, used | {j}, pairs + 1, total + dist[i, j])

    visit(0, frozenset(), 0, 0.0)
    return best


def greedy_loop(dist: np.ndarray, score: np.ndarray, tol: float) -> np.ndarray:
    """Detections by descending score, equal scores in input order; each takes the nearest
    free column closer than ``tol``, the first one on equal distances."""
    out = np.full(dist.shape[0], -1)
    free = [True] * dist.shape[1]
    for i in sorted(range(dist.shape[0]), key=lambda k: (-score[k], k)):
        best_j, best_d = -1, math.inf
        for j in range(dist.shape[1]):
            if free[j] and dist[i, j] < tol and dist[i, j] < best_d:
                best_j, best_d = j, dist[i, j]
        if best_j >= 0:
            out[i] = best_j
            free[best_j] = False
    return out


def nearest_distance_loop(det: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Pixel distance from each detection to its nearest point (inf when there is none)."""
    out = np.full(len(det), math.inf)
    for i, (r, c) in enumerate(det):
        for pr, pc in points:
            out[i] = min(out[i], math.hypot(r - pr, c - pc))
    return out


def xview3_true_positives(dist_m: np.ndarray, tol: float) -> int:
    """Number of true positives of xView3's ``compute_loc_performance`` with ``costly_dist``:
    entries beyond ``tol`` made very costly, a full rectangular assignment, then the assigned
    pairs strictly closer than ``tol`` counted."""
    cost = dist_m.copy()
    cost[cost > tol] = 9999999 * 10
    rows, cols = linear_sum_assignment(cost)
    return sum(1 for r, c in zip(rows, cols, strict=True) if cost[r, c] < tol)
