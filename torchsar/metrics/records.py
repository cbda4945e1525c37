"""The records an object-level state keeps: one per image, one per detection, one per
ground-truth target, in plain numpy record arrays that merge by concatenation.

Every ranked metric (AP, the FROC, Pd at a false-alarm rate, the partial AUC), every
bootstrap replicate, every breakdown and every operating point is computed from these
records when it is read (:class:`~torchsar.metrics.ObjectState`), so no score is ever
binned: a strictly increasing map of the scores changes no number.

Records of any split of a dataset (batches, shards, workers, engines, updates in any order)
hold the same rows; :func:`consolidate` puts them in one canonical order (images by their
order key, detections by rank, targets by image then position) with class and group names
in sorted order, so merged states are equal array for array and every sum over them is
taken in the same order.

Cost: :data:`BYTES_PER_DETECTION` bytes per detection, :data:`BYTES_PER_TARGET` per
ground-truth target and :data:`BYTES_PER_IMAGE` per image.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "BYTES_PER_DETECTION",
    "BYTES_PER_IMAGE",
    "BYTES_PER_TARGET",
    "DETECTION",
    "IMAGE",
    "NOT_FA",
    "TARGET",
    "Records",
    "bit",
    "bits",
    "consolidate",
    "plane_ranks",
]

IMAGE = np.dtype(
    [
        ("order", "<i8"),
        ("unit", "<u8"),
        ("n_gt", "<i4"),
        ("group", "<i4"),
        ("cls", "<i4"),
        ("km2", "<f8"),
    ]
)
"""One image: its order key in the dataset (ties in score are ranked by it, as pycocotools
ranks them by image id), the hash of its bootstrap unit, its ground-truth targets, its group
and image class (indices into the names, -1: none) and its area in km² (NaN: unknown)."""

DETECTION = np.dtype(
    [
        ("score", "<f8"),
        ("image", "<i4"),
        ("rank", "<u4"),
        ("ap_tp", "<u8"),
        ("ap_ig", "<u8"),
        ("op", "u1"),
        ("fa_type", "u1"),
        ("size", "u1"),
        ("label", "<i4"),
        ("iou", "<f8"),
    ]
)
"""One detection: its score (any finite or infinite float), its image (an index into the
image records), its rank among its image's detections, bit ``a * T + t`` of ``ap_tp`` /
``ap_ig`` set when it is a true positive / ignored in COCO area range ``a`` (``all``, then
small, medium, large) at COCO IoU threshold ``t`` (of ``T``), its status under the
matching rule (``op``: 0 false alarm, 1 true positive, 2 ignored), its false-alarm type
(:data:`NOT_FA` when it is none), its size bin, its class (an index into the names, -1:
class-agnostic) and the IoU with the instance it matched under the rule (0: none)."""

TARGET = np.dtype(
    [
        ("image", "<i4"),
        ("index", "<u4"),
        ("found", "<f8"),
        ("size", "u1"),
        ("label", "<i4"),
        ("coco_area", "<f8"),
        ("touch", "<u4"),
        ("scr", "<f8"),
        ("scr_known", "<f8"),
        ("length", "<f8"),
        ("found_length", "<f8"),
    ]
)
"""One ground-truth target: its image, its position among the image's targets, the score of
the detection that matched it under the rule (NaN: missed), its size bin, its class, the
area COCO's area ranges read (the declared one, else its own), the detections touching it,
its measured and known signal-to-clutter ratio in dB, its length and the matched
detection's length in metres (NaN: unknown)."""

NOT_FA = 255
"""``fa_type`` of a detection that is not a false alarm."""

BYTES_PER_DETECTION = DETECTION.itemsize
BYTES_PER_TARGET = TARGET.itemsize
BYTES_PER_IMAGE = IMAGE.itemsize


def plane_ranks(plane: np.ndarray) -> np.ndarray:
    """Position of each object among the objects of its plane, in object order.

    Examples:
        >>> plane_ranks(np.array([1, 0, 1, 1, 0])).tolist()
        [0, 0, 1, 2, 1]
    """
    plane = np.asarray(plane)
    order = np.argsort(plane, kind="stable")
    sorted_planes = plane[order]
    start = np.searchsorted(sorted_planes, sorted_planes, side="left")
    out = np.empty(plane.size, np.int64)
    out[order] = np.arange(plane.size) - start
    return out


def bits(flags: np.ndarray) -> np.ndarray:
    """``(K, M)`` bools as ``(M,)`` uint64 with bit ``k`` set where ``flags[k]`` (K <= 64).

    Examples:
        >>> bits(np.array([[True, False], [True, True]])).tolist()
        [3, 2]
    """
    flags = np.asarray(flags, bool)
    weights = np.left_shift(np.uint64(1), np.arange(flags.shape[0], dtype=np.uint64))[:, None]
    return (flags.astype(np.uint64) * weights).sum(axis=0, dtype=np.uint64)


def bit(values: np.ndarray, k: int) -> np.ndarray:
    """Bit ``k`` of uint64 ``values``, as bool.

    Examples:
        >>> bit(np.array([3, 2], np.uint64), 0).tolist()
        [True, False]
    """
    return ((values >> np.uint64(k)) & np.uint64(1)).astype(bool)


@dataclass(eq=False)
class Records:
    """Image, detection and target records with the names their indices refer to.

    Attributes:
        images: :data:`IMAGE` records.
        detections: :data:`DETECTION` records (``image`` indexes ``images``).
        targets: :data:`TARGET` records.
        names: the class, image-class and group names the records' indices refer to.
    """

    images: np.ndarray = field(default_factory=lambda: np.empty(0, IMAGE))
    detections: np.ndarray = field(default_factory=lambda: np.empty(0, DETECTION))
    targets: np.ndarray = field(default_factory=lambda: np.empty(0, TARGET))
    names: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.images.size)


def _remap(index: np.ndarray, lookup: np.ndarray) -> np.ndarray:
    """``lookup[index]`` where ``index >= 0``, -1 elsewhere."""
    return np.where(index >= 0, lookup[np.maximum(index, 0)] if lookup.size else -1, -1)


def consolidate(parts: list[Records]) -> Records:
    """One :class:`Records` holding every part's records in canonical order (see the module
    docstring).

    Raises:
        ValueError: two images with the same order key (an image added twice).
    """
    names = sorted({n for p in parts for n in p.names})
    at = {n: k for k, n in enumerate(names)}
    images, dets, gts = [], [], []
    offset = 0
    for p in parts:
        lookup = np.array([at[n] for n in p.names], np.int32)
        im = p.images.copy()
        im["group"], im["cls"] = _remap(im["group"], lookup), _remap(im["cls"], lookup)
        d, g = p.detections.copy(), p.targets.copy()
        d["label"], g["label"] = _remap(d["label"], lookup), _remap(g["label"], lookup)
        d["image"] += offset
        g["image"] += offset
        offset += im.size
        images.append(im)
        dets.append(d)
        gts.append(g)
    im = np.concatenate(images) if images else np.empty(0, IMAGE)
    order = np.argsort(im["order"], kind="stable")
    if order.size > 1 and (np.diff(im["order"][order]) == 0).any():
        twice = im["order"][order][np.flatnonzero(np.diff(im["order"][order]) == 0)[0]]
        raise ValueError(f"image order {int(twice)} added twice: states overlap")
    new = np.empty(order.size, np.int32)
    new[order] = np.arange(order.size, dtype=np.int32)
    d = np.concatenate(dets) if dets else np.empty(0, DETECTION)
    g = np.concatenate(gts) if gts else np.empty(0, TARGET)
    d["image"], g["image"] = new[d["image"]], new[g["image"]]
    im = im[order]
    d = d[np.lexsort((d["rank"], d["image"], -d["score"]))]
    g = g[np.lexsort((g["index"], g["image"]))]
    return Records(im, d, g, names)
