"""Exact average precision from per-detection records that merge by concatenation.

A score histogram (:mod:`torchsar.metrics.curves`) is fixed-size but ranks detections only
up to its bin width. AP must rank them exactly, on scores of any range, so every detection
leaves one record: its score, the order key of its image, its rank among its image's
detections, and its status at each IoU threshold (true positive, ignored, else false
positive). Records of any split of a dataset concatenate; ranking them once, by descending
score with ties broken by image order and then by the order within the image, is
``pycocotools``' ranking (a stable sort of the images' score-sorted detections taken in
image order), so AP equals ``COCOeval`` exactly (``useCats=0``, no detection cap).

Cost: :data:`BYTES_PER_DETECTION` bytes per detection (24), beside the fixed-size histograms.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from torchsar.metrics.curves import RECALL_POINTS, interpolated_precision

__all__ = ["BYTES_PER_DETECTION", "RECORD", "RankedDetections", "plane_ranks"]

RECORD = np.dtype(
    [("score", "<f8"), ("image", "<i8"), ("rank", "<u4"), ("tp", "<u2"), ("ignored", "<u2")]
)
"""One detection: score, image order key, rank within the image, and bit ``t`` of ``tp`` /
``ignored`` for IoU threshold ``t`` (at most 16 thresholds)."""

BYTES_PER_DETECTION = RECORD.itemsize


def plane_ranks(plane: np.ndarray) -> np.ndarray:
    """Position of each object among the objects of its plane, in object order.

    Example:
        >>> plane_ranks(np.array([1, 0, 1, 1, 0])).tolist()
        [0, 0, 1, 2, 1]
    """
    order = np.argsort(plane, kind="stable")
    sorted_planes = plane[order]
    start = np.searchsorted(sorted_planes, sorted_planes, side="left")
    out = np.empty(plane.size, np.int64)
    out[order] = np.arange(plane.size) - start
    return out


def _bits(flags: np.ndarray) -> np.ndarray:
    """``(T, M)`` bools as ``(M,)`` integers with bit ``t`` set where ``flags[t]``."""
    weights = (1 << np.arange(flags.shape[0], dtype=np.uint32))[:, None]
    return (flags.astype(np.uint32) * weights).sum(axis=0).astype(np.uint16)


@dataclass(eq=False)
class RankedDetections:
    """Per-detection records of a detector on a set of images (see the module docstring).

    Attributes:
        thresholds: number of IoU thresholds the statuses cover.
        parts: record arrays of :data:`RECORD`, concatenated when ranked.

    Example:
        >>> r = RankedDetections(1)
        >>> r.update(np.array([0.9, 0.8, 0.7]), np.array([0, 0, 1]), np.array([[0, -1, 1]]))
        >>> round(float(r.ap(2)[0]), 4)  # ranked TP, FP, TP: precision 1 to recall 0.5, then 2/3
        0.835
    """

    thresholds: int = 10
    parts: list[np.ndarray] = field(default_factory=list)

    def update(self, score: np.ndarray, image: np.ndarray, status: np.ndarray, rank=None) -> None:
        """Add detections: ``score (M,)``, image order key ``(M,)`` and ``status (T, M)``
        (instance index >= 0: true positive, -1 false positive, -2 ignored). ``rank``
        defaults to the order of each image's detections as given."""
        image = np.asarray(image, dtype=np.int64)
        rec = np.empty(image.size, RECORD)
        rec["score"] = score
        rec["image"] = image
        rec["rank"] = plane_ranks(image) if rank is None else rank
        rec["tp"] = _bits(status >= 0)
        rec["ignored"] = _bits(status == -2)
        self.parts.append(rec)

    def __add__(self, other: RankedDetections) -> RankedDetections:
        if self.thresholds != other.thresholds:
            raise ValueError("cannot add records over different IoU thresholds")
        return RankedDetections(self.thresholds, [*self.parts, *other.parts])

    def __len__(self) -> int:
        return sum(p.size for p in self.parts)

    def ranked(self) -> np.ndarray:
        """Every record in rank order (one sort; cached until the next update)."""
        if len(self.parts) != 1 or not getattr(self, "_sorted", False):
            rec = np.concatenate(self.parts) if self.parts else np.empty(0, RECORD)
            rec = rec[np.lexsort((rec["rank"], rec["image"], -rec["score"]))]
            self.parts, self._sorted = [rec], True
        return self.parts[0]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RankedDetections):
            return NotImplemented
        return self.thresholds == other.thresholds and np.array_equal(self.ranked(),
                                                                       other.ranked())  # fmt: skip

    def __getstate__(self) -> dict:
        return {"thresholds": self.thresholds, "parts": [self.ranked()]}

    def __setstate__(self, state: dict) -> None:
        self.thresholds, self.parts, self._sorted = state["thresholds"], state["parts"], True

    def curves(self, n_gt: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(precision (T, 101), recall (T,), score (T, 101))``: COCO's interpolated
        precision at the recall points, the final recall, and the score of the detection
        where each recall point is reached (NaN where it is not)."""
        rec = self.ranked()
        prec = np.zeros((self.thresholds, RECALL_POINTS.size))
        recall = np.zeros(self.thresholds)
        scores = np.full((self.thresholds, RECALL_POINTS.size), np.nan)
        for t in range(self.thresholds):
            tp = (rec["tp"] >> t) & 1
            fp = 1 - (tp | ((rec["ignored"] >> t) & 1))
            tp_cum, fp_cum = np.cumsum(tp), np.cumsum(fp)
            prec[t], recall[t] = interpolated_precision(tp_cum, fp_cum, n_gt)
            idx = np.searchsorted(tp_cum / n_gt, RECALL_POINTS, side="left")
            ok = idx < rec.size
            scores[t, ok] = rec["score"][idx[ok]]
        return prec, recall, scores

    def ap(self, n_gt: int) -> np.ndarray:
        """AP ``(T,)`` at each IoU threshold (NaN without ground truth)."""
        if n_gt == 0:
            return np.full(self.thresholds, np.nan)
        return self.curves(n_gt)[0].mean(axis=1)
