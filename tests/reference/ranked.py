"""Slow, obvious references of the ranked object metrics: plain Python loops over a list of
detections, one curve point per score level, COCO's interpolation written out.

A detection is a dict ``{score, order, rank, op, ap50}`` (``op`` / ``ap50``: ``"tp"``,
``"fp"`` or ``"ig"``); a resampled dataset repeats each detection of an image drawn ``w``
times ``w`` times in a row (:func:`expand`)."""

from __future__ import annotations

import math

FA_LEVELS = (0.1, 1.0, 10.0)


def ranked(dets: list[dict]) -> list[dict]:
    return sorted(dets, key=lambda d: (-d["score"], d["order"], d["rank"]))


def expand(dets: list[dict], weight_of_image) -> list[dict]:
    """Each detection ``weight_of_image(order)`` times, the copies next to each other."""
    out = []
    for d in ranked(dets):
        out += [d] * int(weight_of_image(d["order"]))
    return out


def froc_points(ordered: list[dict], n_gt: float, images: float) -> list[tuple[float, float]]:
    """``(fa per image, pd)`` at every score level (score >= level) of detections in rank
    order, the origin first."""
    pts = [(0.0, 0.0)]
    tp = fp = 0
    for i, d in enumerate(ordered):
        tp += d["op"] == "tp"
        fp += d["op"] == "fp"
        last = i + 1 == len(ordered) or ordered[i + 1]["score"] != d["score"]
        if last:
            pts.append((fp / max(images, 1), tp / n_gt if n_gt else math.nan))
    return pts


def pd_at(points: list[tuple[float, float]], level: float) -> float:
    best = 0.0
    for fa, pd in points:
        if fa <= level:
            best = max(best, pd)
    return best


def pauc(points: list[tuple[float, float]], limit: float = 1.0) -> float:
    """Area under the step function ``x -> pd_at(points, x)`` over ``[0, limit]``, exactly:
    the function changes only at the points' false-alarm values."""
    xs = sorted({fa for fa, _ in points if fa < limit} | {0.0})
    area = 0.0
    for a, b in zip(xs, [*xs[1:], limit], strict=True):
        area += pd_at(points, a) * (b - a)
    return area / limit


def coco_ap(statuses: list[str], n_gt: float) -> float:
    """COCO's 101-point AP of ranked statuses (``tp``, ``fp``, ``ig``), written out."""
    if n_gt == 0:
        return math.nan
    tp = fp = 0
    recall, precision = [], []
    for s in statuses:
        tp += s == "tp"
        fp += s == "fp"
        recall.append(tp / n_gt)
        precision.append(tp / (tp + fp + 2.220446049250313e-16))
    for i in range(len(precision) - 2, -1, -1):
        precision[i] = max(precision[i], precision[i + 1])
    total = 0.0
    for k in range(101):
        r = k / 100
        q = 0.0
        for rc, p in zip(recall, precision, strict=True):
            if rc >= r:
                q = p
                break
        total += q
    return total / 101


def metrics(
    dets: list[dict], n_gt: float, images: float, threshold: float | None, expanded: bool = False
) -> dict:
    """The headline metrics of (already expanded, in order) or plain detections."""
    order = dets if expanded else ranked(dets)
    kept = [d for d in order if threshold is None or d["score"] > threshold]
    t = sum(d["op"] == "tp" for d in kept)
    f = sum(d["op"] == "fp" for d in kept)
    nan = math.nan
    out = {
        "precision": t / (t + f) if t + f else nan,
        "recall": t / n_gt if n_gt else nan,
        "f1": 2 * t / (2 * t + f + (n_gt - t)) if t + f + n_gt else nan,
        "fom": t / (f + n_gt) if f + n_gt else nan,
        "fa_per_image": f / images if images else nan,
    }
    pts = froc_points(order, n_gt, images)
    for level in FA_LEVELS:
        out[f"pd_at_{level:g}_fa_per_image"] = pd_at(pts, level) if n_gt else nan
    out["pauc"] = pauc(pts) if n_gt else nan
    out["ap50"] = coco_ap([d["ap50"] for d in order], n_gt)
    return out
