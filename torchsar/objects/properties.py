"""Per-object measurements from a label stack: area, box, centroid, length / width, peak."""

from __future__ import annotations

import numpy as np

from torchsar import _jit

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


def _moments(sums: np.ndarray, area: np.ndarray):
    """Centroids ``(n, 2)`` and major / minor axis lengths (``4 sqrt(eigenvalue)`` of the
    central second moments, the convention of ``skimage.measure.regionprops``) from the
    float64 sums ``(5, n)`` of row, column, row^2, column^2 and row x column."""
    r, c, rr, cc, rc = sums / area
    mrr = rr - r * r
    mcc = cc - c * c
    mrc = rc - r * c
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
    appear once per object that owns it, so objects may overlap).

    With the compiled kernels (:func:`torchsar._jit.enabled`) one pass over the pixels
    gathers every reduction (:func:`torchsar.objects._kernels.measure_sums`); its integer
    sums are exact, so the result is the numpy path's bit for bit. Beyond ``2^53`` (a
    sum of squared coordinates that float64 could not hold exactly) numpy's path is
    taken."""
    h, w = hw
    if _jit.enabled() and lab.size * max(h, w) ** 2 < 2**53:
        from torchsar.objects import _kernels

        plane, lo, hi, sums, peak = _kernels.measure_sums(lab, idx, hw, n, values)
        area = sums[0]
        box = np.stack([lo[0], lo[1], hi[0] + 1, hi[1] + 1], axis=1).astype(np.float64)
        moments = sums[1:].astype(np.float64)
    else:
        r, c = (idx // w) % h, idx % w
        rows, cols = r.astype(np.float64), c.astype(np.float64)
        area = np.bincount(lab, minlength=n + 1)[1:].astype(np.int64)
        groups = _Groups(lab, n)
        plane, box = _plane_and_box(groups, idx, (h, w), n)
        moments = np.stack(
            [groups.sum(v) for v in (rows, cols, rows * rows, cols * cols, rows * cols)]
        ).reshape(5, n)
        peak = groups.max(np.asarray(values, dtype=np.float64), -np.inf)
    centroid, length, width = _moments(moments, np.maximum(area, 1))
    return {
        "plane": plane,
        "area": area,
        "box": box.reshape(n, 4),
        "centroid": centroid,
        "length": length,
        "width": width,
        "score": peak,
    }
