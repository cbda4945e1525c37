"""Per-object measurements from a label stack: area, box, centroid, length / width, peak."""

from __future__ import annotations

import numpy as np

__all__ = ["label_boxes", "measure", "measure_pixels"]


class _Groups:
    """Per-label reductions of pixel values (labels ``1..n``): minima and maxima by
    contiguous runs of the labels (sorted once, stably, unless they come sorted: objects
    given pixel list by pixel list); sums by contiguous runs only when the labels come
    sorted, else by scatter in pixel order (a sum's rounding depends on its order)."""

    def __init__(self, lab: np.ndarray, n: int) -> None:
        self.lab, self.n = lab, n
        self.runs = lab.size < 2 or bool((lab[1:] >= lab[:-1]).all())
        self.order = None if self.runs else np.argsort(lab, kind="stable")
        ordered = lab if self.order is None else lab[self.order]
        self.starts = np.flatnonzero(np.diff(ordered, prepend=-1) != 0)
        self.labels = ordered[self.starts]

    def _reduce(self, ufunc: np.ufunc, values: np.ndarray, fill) -> np.ndarray:
        out = np.full(self.n + 1, fill, dtype=np.result_type(values, type(fill)))
        if self.starts.size:
            ordered = values if self.order is None else values[self.order]
            out[self.labels] = ufunc.reduceat(ordered, self.starts)
        return out[1:]

    def sum(self, values: np.ndarray) -> np.ndarray:
        if not self.runs:
            return np.bincount(self.lab, weights=values, minlength=self.n + 1)[1:]
        return self._reduce(np.add, values, 0.0)

    def min(self, values: np.ndarray, fill) -> np.ndarray:
        return self._reduce(np.minimum, values, fill)

    def max(self, values: np.ndarray, fill) -> np.ndarray:
        return self._reduce(np.maximum, values, fill)


def _extent(groups: _Groups, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-label minimum and maximum of integer ``values``."""
    return groups.min(values, np.iinfo(np.int64).max), groups.max(values, -1)


def _moments(groups: _Groups, rows: np.ndarray, cols: np.ndarray, area: np.ndarray):
    """Centroids ``(n, 2)`` and major / minor axis lengths (``4 sqrt(eigenvalue)`` of the
    central second moments, the convention of ``skimage.measure.regionprops``)."""

    def mean(w: np.ndarray) -> np.ndarray:
        return groups.sum(w) / area

    r, c = mean(rows), mean(cols)
    mrr = mean(rows * rows) - r * r
    mcc = mean(cols * cols) - c * c
    mrc = mean(rows * cols) - r * c
    half = 0.5 * (mrr + mcc)
    root = np.sqrt(np.maximum(0.25 * (mrr - mcc) ** 2 + mrc**2, 0.0))
    length = 4 * np.sqrt(np.maximum(half + root, 0.0))
    width = 4 * np.sqrt(np.maximum(half - root, 0.0))
    return np.stack([r, c], axis=1), length, width


def label_boxes(labels: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Plane ``(n,)`` and end-exclusive box ``(n, 4)`` ``(r0, c0, r1, c1)`` of labels ``1..n``
    of a stack ``(N, H, W)`` (ids unique across planes), from the labelled pixels only."""
    flat = labels.reshape(-1)
    idx = np.flatnonzero(flat)
    lab = flat[idx].astype(np.int64)
    return _plane_and_box(_Groups(lab, n), idx, labels.shape[-2:], n)


def _plane_and_box(groups: _Groups, idx: np.ndarray, hw: tuple[int, int], n: int):
    h, w = hw
    plane = _extent(groups, idx // (h * w))[0]
    (r0, r1), (c0, c1) = _extent(groups, (idx // w) % h), _extent(groups, idx % w)
    box = np.stack([r0, c0, r1 + 1, c1 + 1], axis=1).astype(np.float64).reshape(n, 4)
    return plane, box


def measure(labels: np.ndarray, n: int, score: np.ndarray) -> dict[str, np.ndarray]:
    """Measure objects ``1..n`` of a label stack ``(N, H, W)`` (ids unique across planes).

    Returns a dict of arrays, one entry per object in id order: ``plane``, ``area``,
    ``box``, ``centroid`` (row, col), ``length``, ``width`` and ``score`` (the maximum of
    ``score`` over the object's pixels).
    """
    flat = labels.reshape(-1)
    idx = np.flatnonzero(flat)
    lab = flat[idx].astype(np.int64)
    return measure_pixels(lab, idx, labels.shape[-2:], n, score.reshape(-1)[idx])


def measure_pixels(
    lab: np.ndarray, idx: np.ndarray, hw: tuple[int, int], n: int, values: np.ndarray
) -> dict[str, np.ndarray]:
    """:func:`measure` from pixel lists: object id ``lab`` (``1..n``) of every pixel, its
    flat index ``idx`` into the ``(N, H, W)`` stack and its score ``values`` (a pixel may
    appear once per object that owns it, so objects may overlap)."""
    h, w = hw
    r, c = (idx // w) % h, idx % w
    rows, cols = r.astype(np.float64), c.astype(np.float64)
    area = np.bincount(lab, minlength=n + 1)[1:].astype(np.int64)
    groups = _Groups(lab, n)
    plane, box = _plane_and_box(groups, idx, (h, w), n)
    centroid, length, width = _moments(groups, rows, cols, np.maximum(area, 1))
    peak = groups.max(np.asarray(values, dtype=np.float64), -np.inf)
    return {
        "plane": plane,
        "area": area,
        "box": box,
        "centroid": centroid,
        "length": length,
        "width": width,
        "score": peak,
    }
