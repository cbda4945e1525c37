"""One-to-one matching of scored objects to ground-truth instances.

The COCO rule (Lin et al., "Microsoft COCO: Common Objects in Context", ECCV 2014,
doi:10.1007/978-3-319-10602-1_48; the ``pycocotools`` evaluator): detections are visited in
descending score order; each takes the still-unmatched ground-truth instance of highest
quality (mask or box IoU) at or above the threshold; an instance is matched at most once; a
detection matching nothing real but overlapping the image's ignore region (COCO "crowd":
intersection over the detection's own area) is ignored, neither true nor false. So one blob
over two targets is at most one true positive, and a flood of the whole image is one false
alarm. Because the visit is greedy by score, the matches among the detections scoring above
any level are exactly those of the full pass: one pass gives every point of a PR / FROC curve.

The prescreening rule (``kind="centroid"``), common for SAR vehicle prescreeners: a detection
hits an instance when its centroid lies inside the instance's box grown by ``margin`` (a
fraction of the box's larger side) and its box is at most ``max_size_ratio`` times the
instance's box area; among several, the nearest box centre; the same greedy one-to-one visit.

The distance rule (``kind="distance"``), for point detectors (xView3-SAR): a detection's
centroid and an instance's centroid pair up when closer than ``max_distance`` (pixels, or
metres with each image's pixel spacing); see :mod:`torchsar.metrics.points`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import cached_property

import numpy as np

from torchsar._checks import OptionError, check_choice, check_ids, check_same_shape

__all__ = [
    "COCO_IOUS",
    "GroundTruth",
    "Matching",
    "box_iou",
    "first_reach",
    "greedy_match",
    "greedy_match_planes",
    "ground_truth",
    "ignore_boxes",
    "mask_overlaps",
    "pair_box_iou",
]

COCO_IOUS = np.linspace(0.5, 0.95, 10)
"""The IoU thresholds of COCO's AP@[.5:.95], exactly as ``pycocotools`` computes them (its
0.9 is 0.8999999999999999: rounding it would refuse an IoU of exactly that value)."""

UNMATCHED, IGNORED = -1, -2


@dataclass(frozen=True)
class Matching:
    """The matching rule of the operating-point metrics and the FROC.

    Attributes:
        kind: ``"mask"`` (mask IoU), ``"box"`` (box IoU), ``"centroid"`` (prescreening) or
            ``"distance"`` (points closer than ``max_distance``).
        iou: IoU threshold of ``mask`` / ``box`` (0.5: PASCAL VOC / COCO AP50).
        margin: ``centroid`` rule: box growth, as a fraction of the box's larger side.
        max_size_ratio: ``centroid`` rule: largest detection-box / instance-box area ratio.
        max_distance: ``distance`` rule: the tolerance (strict), in ``distance_units``.
        distance_units: ``"px"`` or ``"m"`` (with each image's pixel spacing).
        assign: ``distance`` rule at the operating point: ``"optimal"`` (the most pairs,
            then the least total distance, as xView3-SAR) or ``"greedy"`` (by score). AP and
            the FROC always use the greedy visit by score.
    """

    kind: str = "mask"
    iou: float = 0.5
    margin: float = 0.25
    max_size_ratio: float = 4.0
    max_distance: float | None = None
    distance_units: str = "px"
    assign: str = "optimal"

    def __post_init__(self) -> None:
        check_choice(self.kind, "kind", ("mask", "box", "centroid", "distance"))
        for name, lo, hi in (("iou", 0.0, 1.0), ("margin", 0.0, 10.0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= v <= hi:
                raise OptionError(f"{name} must be in [{lo:g}, {hi:g}], got {v!r}")
        r = self.max_size_ratio
        if isinstance(r, bool) or not isinstance(r, int | float) or not r >= 1:
            raise OptionError(f"max_size_ratio must be >= 1, got {r!r}")
        check_choice(self.distance_units, "distance_units", ("px", "m"))
        check_choice(self.assign, "assign", ("optimal", "greedy"))
        d = self.max_distance
        if self.kind == "distance" and d is None:
            raise OptionError("the distance rule needs max_distance (pixels or metres)")
        if d is not None and (isinstance(d, bool) or not isinstance(d, int | float)
                              or not 0 < d < float("inf")):  # fmt: skip
            raise OptionError(f"max_distance must be a finite number > 0, got {d!r}")

    @property
    def iou_kind(self) -> str:
        """The IoU used for AP: box IoU under the box rule, mask IoU otherwise."""
        return "box" if self.kind == "box" else "mask"

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class GroundTruth:
    """Ground-truth instances of a stack of planes (ids unique across the stack).

    Attributes:
        ids: int64 ``(N, H, W)`` instance ids ``1..G`` (0 = none); instance ``k`` has id
            ``k + 1``.
        plane: int64 ``(G,)``; area: int64 ``(G,)`` pixels; box: float64 ``(G, 4)``
            ``(r0, c0, r1, c1)`` end-exclusive; classes: ``(G,)`` object array of str.
        ignore: bool ``(N, H, W)`` don't-care pixels.
        box_only: bool ``(N,)`` planes whose ground truth is boxes only (box IoU there).
        centroid: float64 ``(G, 2)`` (row, col) pixel-index centroid (a box-only
            instance's box centre).
        spacing: float64 ``(N, 2)`` pixel spacing (row, col) in metres, NaN if unknown.
        length_m: float64 ``(G,)`` declared lengths in metres (NaN where unknown).
        declared_area: float64 ``(G,)`` areas the annotations declare (COCO ``area``; NaN
            where unknown), used for COCO's area ranges.
        known_scr_db: float64 ``(G,)`` signal-to-clutter ratios in dB the data declare
            (a simulator's known value; NaN where unknown), or ``None``.
        scr_db: float64 ``(G,)`` signal-to-clutter ratios in dB measured on the image
            (:func:`torchsar.metrics.scr.target_scr_db`), or ``None`` (not measured).
        shadow: bool ``(N,)`` planes whose ignore pixels are radar shadow, or ``None``
            (unknown: no plane's).
    """

    ids: np.ndarray
    plane: np.ndarray
    area: np.ndarray
    box: np.ndarray
    classes: np.ndarray
    ignore: np.ndarray
    box_only: np.ndarray
    centroid: np.ndarray | None = None
    spacing: np.ndarray | None = None
    length_m: np.ndarray | None = None
    declared_area: np.ndarray | None = None
    known_scr_db: np.ndarray | None = None
    scr_db: np.ndarray | None = None
    shadow: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.plane.shape[0])

    @cached_property
    def ignore_boxes(self) -> np.ndarray:
        """Bounding box ``(r0, c0, r1, c1)`` of each plane's ignore pixels ``(N, 4)`` (zero
        box when none), computed once for every detector matched against these."""
        return ignore_boxes(self.ignore)


def ignore_boxes(ignore: np.ndarray) -> np.ndarray:
    """Bounding box of each plane's ignore pixels ``(N, 4)`` (zero box when none).

    Example:
        >>> ig = np.zeros((2, 4, 4), bool); ig[1, 1:3, 2] = True
        >>> ignore_boxes(ig).tolist()
        [[0.0, 0.0, 0.0, 0.0], [1.0, 2.0, 3.0, 3.0]]
    """
    rows, cols = ignore.any(axis=2), ignore.any(axis=1)
    out = np.zeros((ignore.shape[0], 4))
    for p in np.flatnonzero(rows.any(axis=1)):
        r, c = np.flatnonzero(rows[p]), np.flatnonzero(cols[p])
        out[p] = (r[0], c[0], r[-1] + 1, c[-1] + 1)
    return out


def ground_truth(
    instances: np.ndarray,
    ignore: np.ndarray | None = None,
    *,
    classes: list[list[str]] | None = None,
    boxes: list[list] | None = None,
    box_only: np.ndarray | None = None,
    spacing: np.ndarray | None = None,
    lengths: list[list] | None = None,
    areas: list[list] | None = None,
    known_scr_db: list[list] | None = None,
    shadow: np.ndarray | None = None,
) -> GroundTruth:
    """Build :class:`GroundTruth` from instance-id planes ``(N, H, W)``.

    Args:
        instances: integer ids per plane (0 = none; any positive ids). Floating ids are
            accepted when they are whole numbers.
        ignore: bool don't-care pixels, same shape (default none).
        classes: per plane, the class of local id ``k`` at position ``k - 1`` (default
            ``"target"``).
        boxes: per plane, the box of local id ``k`` at position ``k - 1`` (default: the
            bounding box of the id's pixels); required to be exact for box-only planes.
        box_only: bool per plane (default all False).
        spacing: ``(N, 2)`` pixel spacing per plane in metres (NaN: unknown).
        lengths: per plane, the length in metres of local id ``k`` at position ``k - 1``.
        areas: per plane, the declared area of local id ``k`` at position ``k - 1``.
        known_scr_db: per plane, the known signal-to-clutter ratio in dB of local id ``k``
            at position ``k - 1`` (``None``: unknown).
        shadow: bool per plane: its ignore pixels are radar shadow (default: unknown).

    Raises:
        InputTypeError: ``instances`` is not numeric, or holds fractional, NaN or infinite
            floating ids.
        InputValueError: ``instances`` holds a negative id.
        ShapeError: ``instances`` is not ``(N, H, W)``, or ``ignore`` has another shape.
    """
    inst = check_ids(instances, "instances", ndim=3)
    if ignore is not None:
        check_same_shape(np.asarray(ignore), inst, "ignore", "instances")
    n_planes = inst.shape[0]
    flat = inst.reshape(-1)
    idx = np.flatnonzero(flat)  # the labelled pixels: everything below works on them only
    hw = int(np.prod(inst.shape[1:]))
    pix_plane = idx // hw
    key = pix_plane * (int(flat.max(initial=0)) + 1) + flat[idx].astype(np.int64)
    keys, inv = np.unique(key, return_inverse=True)  # planes in order, then local ids
    n = int(keys.size)
    ids = np.zeros(inst.shape, np.int64)
    ids.reshape(-1)[idx] = inv + 1
    plane = keys // (int(flat.max(initial=0)) + 1)
    local = keys - plane * (int(flat.max(initial=0)) + 1)
    area = np.bincount(inv, minlength=n).astype(np.int64)
    box, centroid = _boxes_and_centroids(idx, inv, inst.shape[-2:], n, area)
    cls = np.array(["target"] * n, dtype=object)
    length_m = np.full(n, np.nan)
    declared = np.full(n, np.nan)
    known = np.full(n, np.nan)
    for k in range(n):
        p, i = int(plane[k]), int(local[k]) - 1
        if classes is not None and i < len(classes[p]):
            cls[k] = str(classes[p][i])
        if boxes is not None and i < len(boxes[p]):
            box[k] = np.asarray(boxes[p][i], dtype=np.float64)
        if lengths is not None and i < len(lengths[p]) and lengths[p][i] is not None:
            length_m[k] = float(lengths[p][i])
        if areas is not None and i < len(areas[p]) and areas[p][i] is not None:
            declared[k] = float(areas[p][i])
        if known_scr_db is not None and i < len(known_scr_db[p]) and (
                known_scr_db[p][i] is not None):  # fmt: skip
            known[k] = float(known_scr_db[p][i])
    ig = np.zeros(inst.shape, bool) if ignore is None else np.asarray(ignore, bool)
    bo = np.zeros(n_planes, bool) if box_only is None else np.asarray(box_only, bool)
    sp = np.full((n_planes, 2), np.nan) if spacing is None else np.asarray(spacing, np.float64)
    on_box = bo[plane] if n else np.zeros(0, bool)
    centroid[on_box] = 0.5 * (box[on_box, :2] + box[on_box, 2:]) - 0.5
    shade = None if shadow is None else np.asarray(shadow, bool).reshape(n_planes)
    return GroundTruth(ids, plane.astype(np.int64), area, box, cls, ig & (ids == 0), bo,
                       centroid, sp.reshape(n_planes, 2), length_m, declared,
                       None if known_scr_db is None else known, None, shade)  # fmt: skip


def _boxes_and_centroids(idx: np.ndarray, inv: np.ndarray, hw, n: int, area: np.ndarray):
    """End-exclusive boxes ``(n, 4)`` and mean (row, col) ``(n, 2)`` of instances ``inv``
    of the labelled pixels ``idx`` (flat indices into the stack)."""
    h, w = hw
    rows, cols = (idx // w) % h, idx % w
    box = np.zeros((n, 4))
    for axis, coord in enumerate((rows, cols)):
        lo = np.full(n, np.iinfo(np.int64).max)
        hi = np.full(n, -1)
        np.minimum.at(lo, inv, coord)
        np.maximum.at(hi, inv, coord)
        box[:, axis], box[:, axis + 2] = lo, hi + 1
    centroid = np.stack([np.bincount(inv, weights=c, minlength=n) for c in (rows, cols)], axis=1)
    return box, centroid / np.maximum(area, 1)[:, None]


def mask_overlaps(
    det: np.ndarray, n_det: int, gt: np.ndarray, n_gt: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sparse pixel intersections of two label stacks: ``(det_index, gt_index, pixels)``
    for every overlapping pair (0-based indices)."""
    d, g = det.reshape(-1), gt.reshape(-1)
    both = (d > 0) & (g > 0)
    key = d[both].astype(np.int64) * (n_gt + 1) + g[both]
    pairs, inter = np.unique(key, return_counts=True)
    return pairs // (n_gt + 1) - 1, pairs % (n_gt + 1) - 1, inter


def box_iou(a: np.ndarray, b: np.ndarray, *, crowd: bool = False) -> np.ndarray:
    """IoU matrix ``(len(a), len(b))`` of end-exclusive boxes ``(r0, c0, r1, c1)``; with
    ``crowd`` the intersection over the area of ``a`` (COCO's crowd rule).

    Example:
        >>> box_iou(np.array([[0, 0, 2, 2.]]), np.array([[0, 1, 2, 3.]])).tolist()
        [[0.3333333333333333]]
    """
    return pair_box_iou(a[:, None, :], b[None, :, :], crowd=crowd)


def pair_box_iou(a: np.ndarray, b: np.ndarray, *, crowd: bool = False) -> np.ndarray:
    """:func:`box_iou` of boxes ``a[..., :]`` and ``b[..., :]`` paired by broadcasting."""
    ih = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0, None)
    iw = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0, None)
    inter = ih * iw
    area_a = (a[..., 2] - a[..., 0]) * (a[..., 3] - a[..., 1])
    area_b = (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1])
    den = area_a if crowd else area_a + area_b - inter
    return np.where(den > 0, inter / np.where(den > 0, den, 1.0), 0.0)


def greedy_match(quality: np.ndarray, crowd: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    """COCO's greedy one-to-one assignment at several thresholds at once.

    Args:
        quality: ``(D, G)`` pair quality (IoU), detections already in descending score order.
        crowd: ``(D,)`` quality against the ignore region (used only when no instance matches).
        thresholds: ``(T,)`` minimum quality (a pair at exactly the threshold matches).

    Returns:
        int ``(T, D)``: the matched instance column, ``-1`` unmatched, ``-2`` ignored.
        Among instances of equal quality the last one wins, as in ``pycocotools``.
    """
    n_t, (n_d, n_g) = len(thresholds), quality.shape
    thr = _clip(thresholds)
    if n_g <= 1:
        return _greedy_single(quality, crowd, thr)
    out = np.full((n_t, n_d), UNMATCHED, dtype=np.int64)
    best = quality.max(axis=1, initial=0.0) if n_g else np.zeros(n_d)
    cand = np.flatnonzero((best >= thr.min()) | (crowd >= thr.min()))
    taken = np.zeros((n_t, n_g), bool)
    rows = np.arange(n_t)
    for d in cand:
        if n_g:
            q = np.where(~taken & (quality[d][None, :] >= thr[:, None]), quality[d][None, :], -1.0)
            j = n_g - 1 - np.argmax(q[:, ::-1], axis=1)
            hit = q[rows, j] >= 0
            out[hit, d] = j[hit]
            taken[rows[hit], j[hit]] = True
        else:
            hit = np.zeros(n_t, bool)
        out[~hit & (crowd[d] >= thr), d] = IGNORED
    return out


def greedy_match_planes(
    quality: np.ndarray, crowd: np.ndarray, thresholds: np.ndarray
) -> np.ndarray:
    """:func:`greedy_match` of many planes at once, one detection rank at a time.

    Args:
        quality: ``(P, D, G)`` pair quality per plane, detections in descending score order,
            padded with -1 (a padded detection or instance never matches).
        crowd: ``(P, D)`` crowd quality (-1 for padding).
        thresholds: ``(T,)`` minimum quality.

    Returns:
        int ``(T, P, D)``: matched instance column, -1 unmatched, -2 ignored.

    Example:
        >>> q = np.array([[[0.9, 0.6], [0.8, 0.0]]])  # one plane, two detections, two instances
        >>> greedy_match_planes(q, np.zeros((1, 2)), np.array([0.5]))[0].tolist()
        [[0, -1]]
    """
    n_p, n_d, n_g = quality.shape
    thr = _clip(thresholds)
    out = np.full((thr.size, n_p, n_d), UNMATCHED, dtype=np.int64)
    taken = np.zeros((thr.size, n_p, n_g), bool)
    tt, pp = np.meshgrid(np.arange(thr.size), np.arange(n_p), indexing="ij")
    for d in range(n_d):
        q = quality[None, :, d, :]  # (1, P, G)
        q = np.where(~taken & (q >= thr[:, None, None]), q, -1.0)  # (T, P, G)
        j = n_g - 1 - np.argmax(q[..., ::-1], axis=2) if n_g else np.zeros((thr.size, n_p), int)
        hit = (q[tt, pp, j] >= 0) if n_g else np.zeros((thr.size, n_p), bool)
        out[tt[hit], pp[hit], d] = j[hit]
        taken[tt[hit], pp[hit], j[hit]] = True
        out[:, :, d][~hit & (crowd[None, :, d] >= thr[:, None])] = IGNORED
    return out


def _clip(thresholds: np.ndarray) -> np.ndarray:
    """Thresholds as float64, 1 lowered to ``1 - 1e-10`` (as ``pycocotools``)."""
    return np.minimum(np.asarray(thresholds, dtype=np.float64), 1 - 1e-10)


def _greedy_single(quality: np.ndarray, crowd: np.ndarray, thr: np.ndarray) -> np.ndarray:
    """:func:`greedy_match` for at most one instance (column 0), by :func:`first_reach`."""
    n_d = quality.shape[0]
    q = quality[:, 0] if quality.shape[1] else np.full(n_d, np.nan)
    return first_reach(q, crowd, thr, np.zeros(n_d, np.int64))


def first_reach(
    quality: np.ndarray, crowd: np.ndarray, thresholds: np.ndarray, start: np.ndarray
) -> np.ndarray:
    """:func:`greedy_match` for many groups of detections (e.g. planes) that each compete for
    at most one instance (a chip with one target), all at once: at each threshold the first
    detection of a group reaching it takes the instance; the others are ignored where their
    crowd quality reaches it.

    Args:
        quality: ``(D,)`` quality of each detection with its group's instance (NaN: the
            group has none); detections grouped, in descending score order within a group.
        crowd: ``(D,)`` quality against the ignore region.
        thresholds: ``(T,)`` minimum quality.
        start: ``(D,)`` index of the first detection of each detection's group.

    Returns:
        int ``(T, D)``: ``0`` matched (the group's instance), ``-1`` unmatched, ``-2`` ignored.
    """
    thr = _clip(thresholds)[:, None]
    reach = quality[None, :] >= thr  # NaN never reaches
    seen = np.cumsum(reach, axis=1)
    before = np.where(start > 0, seen[:, np.maximum(start - 1, 0)], 0)
    first = reach & (seen - before == 1)
    out = np.where(first, 0, UNMATCHED)
    out[~first & (crowd[None, :] >= thr)] = IGNORED
    return out
