"""Slow references for object-level counts: explicit sets of pixels per component."""

from __future__ import annotations

import numpy as np
from skimage.measure import label


def object_scores(pred: np.ndarray, inst: np.ndarray, ignore: np.ndarray | None = None) -> dict:
    comps = label(pred, connectivity=2)
    n = comps.max()
    ids = [i for i in np.unique(inst) if i > 0]
    detected, frags, ious = 0, 0, []
    for i in ids:
        region = inst == i
        touching = {c for c in np.unique(comps[region]) if c > 0}
        if touching:
            detected += 1
            frags += len(touching)
            union_comp = np.isin(comps, list(touching))
            ious.append((region & union_comp).sum() / (region | union_comp).sum())
    fa = 0
    for c in range(1, n + 1):
        comp = comps == c
        if (inst[comp] > 0).any():
            continue
        if ignore is not None and ignore[comp].all():
            continue
        fa += 1
    return {
        "instances": len(ids),
        "detected": detected,
        "false_alarms": fa,
        "fragments": frags,
        "iou_sum": float(np.sum(ious)),
    }
