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
