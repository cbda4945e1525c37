"""A literal port of pycocotools' per-image greedy matching loop (``COCOeval.evaluateImg``),
one threshold at a time, for checking the vectorised matcher."""

from __future__ import annotations

import numpy as np


def coco_match(ious: np.ndarray, is_crowd: np.ndarray, thresholds) -> np.ndarray:
    """``ious`` (D, G) with detections in score order and crowd columns flagged; returns
    (T, D): matched column, -1 unmatched, -2 matched to a crowd column."""
    order = np.argsort(is_crowd, kind="mergesort")  # non-crowd first, as pycocotools
    out = np.full((len(thresholds), ious.shape[0]), -1)
    for ti, t in enumerate(thresholds):
        gtm = np.zeros(ious.shape[1], bool)
        for d in range(ious.shape[0]):
            iou, m = min(t, 1 - 1e-10), -1
            for g in order:
                if gtm[g] and not is_crowd[g]:
                    continue
                if m > -1 and not is_crowd[m] and is_crowd[g]:
                    break
                if ious[d, g] < iou:
                    continue
                iou, m = ious[d, g], g
            if m == -1:
                continue
            out[ti, d] = -2 if is_crowd[m] else m
            gtm[m] = True
    return out


def random_problems(rng: np.random.Generator, problems: int, ranges: int) -> tuple:
    """Random matching problems for :func:`torchsar.metrics.greedy.assign_pairs`: up to 8
    detections and instances each, instances ignored in some of ``ranges`` area ranges,
    some crowd (ignored everywhere), qualities with ties. Returns ``(d_problem, g_problem,
    ignore, crowd, pairs, dense)``: the flat candidate pairs ``(d, g, quality)`` and each
    problem's ``(D, G)`` quality block (0: not a candidate)."""
    sizes = rng.integers(0, 9, (problems, 2))
    d_problem = np.repeat(np.arange(problems), sizes[:, 0])
    g_problem = np.repeat(np.arange(problems), sizes[:, 1])
    ignore = rng.random((g_problem.size, ranges)) < 0.3
    crowd = rng.random(g_problem.size) < 0.2
    ignore[crowd] = True
    pairs, dense, d0, g0 = ([], [], []), [], 0, 0
    for d, g in sizes:
        q = rng.choice([0.0, 0.3, 0.5, 0.55, 0.7, 0.9, 1.0], size=(d, g))
        dense.append(q)
        i, j = np.nonzero(q > 0)
        for a, v in zip(pairs, (i + d0, j + g0, q[i, j]), strict=True):
            a.append(v)
        d0, g0 = d0 + d, g0 + g
    flat = tuple(np.concatenate(a) for a in pairs)
    return d_problem, g_problem, ignore, crowd, flat, dense
