"""Ground truth as given: every target a separate object (a mask or a box, overlapping
others or not), and don't-care regions kept apart, each with its own class.

:class:`GroundTruth` holds the targets of a stack of planes (the images of a batch) the way
:class:`~torchsar.objects.Objects` holds detections: per target its plane, class, box, area
and, when it is a mask, its pixels (flat indices into the ``(N, H, W)`` stack, compressed
row by row). Two targets may share pixels (berthed ships, overlapping COCO boxes): nothing
is painted into one plane, so neither loses pixels to the other. A box target stays a box:
it has no pixels unless given some, and box ground truth with box detections never touches
a pixel plane.

Don't-care regions (:class:`Regions`: COCO crowd annotations, VOC ``difficult`` objects, a
simulator's radar shadows) are separate: a detection that matches no target but lies on one
(its share on the region, of its own area, reaches the IoU threshold: COCO's crowd rule) is
neither true nor false. A region with a class applies to detections of that class only (in
class-aware matching); a region without one to every detection.

Dense views for code that works on pixel planes (the signal-to-clutter measurement, the
gallery) are built on demand: :attr:`GroundTruth.ids` paints the targets in order (a later
target wins where two overlap) and :attr:`GroundTruth.ignore` rasterises the regions.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from torchsar._checks import check_ids, check_same_shape
from torchsar.errors import ShapeError
from torchsar.objects import ObjectMasks

__all__ = ["GroundTruth", "Regions", "box_pixels", "ground_truth"]


def _csr(pixels: Sequence[np.ndarray | None], n: int) -> ObjectMasks:
    """Per-object flat index arrays (``None``: no pixels) as :class:`ObjectMasks`."""
    counts = np.array([0 if p is None else len(p) for p in pixels], np.int64).reshape(n)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    parts = [np.asarray(p, np.int64).reshape(-1) for p in pixels if p is not None and len(p)]
    flat = np.concatenate(parts) if parts else np.zeros(0, np.int64)
    return ObjectMasks(offsets, flat)


def _no_pixels(n: int) -> ObjectMasks:
    """:class:`ObjectMasks` of ``n`` objects without pixels."""
    return ObjectMasks(np.zeros(n + 1, np.int64), np.zeros(0, np.int64))


def box_pixels(box: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Flat in-plane indices of the pixels whose centres lie in a box ``(r0, c0, r1, c1)``
    (end-exclusive), clipped to the plane.

    Examples:
        >>> box_pixels(np.array([0.0, 1.0, 2.0, 3.0]), (4, 4)).tolist()
        [1, 2, 5, 6]
    """
    h, w = shape
    r0, c0 = (max(int(np.ceil(v - 0.5)), 0) for v in box[:2])
    r1, c1 = min(int(np.ceil(box[2] - 0.5)), h), min(int(np.ceil(box[3] - 0.5)), w)
    if r1 <= r0 or c1 <= c0:
        return np.zeros(0, np.int64)
    rr, cc = np.meshgrid(np.arange(r0, r1), np.arange(c0, c1), indexing="ij")
    return (rr * w + cc).reshape(-1).astype(np.int64)


@dataclass(frozen=True, eq=False)
class Regions:
    """Don't-care regions of a stack of planes (see the module docstring).

    Attributes:
        plane: int64 ``(K,)`` plane of each region.
        classes: object ``(K,)`` the class a region applies to (``None``: every class).
        box: float64 ``(K, 4)`` ``(r0, c0, r1, c1)`` end-exclusive.
        masks: the regions' pixels (flat stack indices); none for a box region.
        has_mask: bool ``(K,)`` whether a region is its pixels (else its box).
    """

    plane: np.ndarray
    classes: np.ndarray
    box: np.ndarray
    masks: ObjectMasks
    has_mask: np.ndarray

    def __len__(self) -> int:
        return int(self.plane.size)

    @classmethod
    def none(cls) -> Regions:
        """No region."""
        return cls(
            np.zeros(0, np.int64),
            np.zeros(0, object),
            np.zeros((0, 4)),
            _csr([], 0),
            np.zeros(0, bool),
        )

    @classmethod
    def from_planes(cls, ignore: np.ndarray) -> Regions:
        """One region of every class per plane: the plane's don't-care pixels (``(N, H, W)``
        bool).

        Examples:
            >>> ig = np.zeros((2, 4, 4), bool); ig[1, 1:3, 2] = True
            >>> r = Regions.from_planes(ig)
            >>> r.plane.tolist(), r.box.tolist(), r.masks.pixels.tolist()
            ([1], [[1.0, 2.0, 3.0, 3.0]], [22, 26])
        """
        ig = np.asarray(ignore, bool)
        h, w = ig.shape[1:]
        idx = np.flatnonzero(ig.reshape(-1))
        plane, local = idx // (h * w), idx % (h * w)
        planes, counts = np.unique(plane, return_counts=True)
        box = np.zeros((planes.size, 4))
        r, c = local // w, local % w
        starts = np.cumsum(counts) - counts
        for k, (s, m) in enumerate(zip(starts, counts, strict=True)):
            rr, cc = r[s : s + m], c[s : s + m]
            box[k] = (rr.min(), cc.min(), rr.max() + 1, cc.max() + 1)
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        masks = ObjectMasks(offsets, idx.astype(np.int64))
        none = np.full(planes.size, None, object)
        return cls(planes.astype(np.int64), none, box, masks, np.ones(planes.size, bool))

    @classmethod
    def build(
        cls,
        plane: np.ndarray,
        box: np.ndarray,
        *,
        shape: tuple[int, int],
        classes: Sequence[str | None] | None = None,
        pixels: Sequence[np.ndarray | None] | None = None,
    ) -> Regions:
        """Regions from their planes, boxes, classes (``None``: every class) and pixels
        (flat in-plane indices; ``None`` for a box region)."""
        plane = np.asarray(plane, np.int64).reshape(-1)
        k = plane.size
        box = np.asarray(box, np.float64).reshape(k, 4)
        h, w = shape
        cls_ = (
            np.full(k, None, object)
            if classes is None
            else np.array([None if c is None else str(c) for c in classes], dtype=object)
        )
        if pixels is None:  # box regions only
            return cls(plane, cls_.reshape(k), box, _no_pixels(k), np.zeros(k, bool))
        pix = list(pixels)
        stack = [
            None if p is None else np.asarray(p, np.int64) + plane[i] * h * w
            for i, p in enumerate(pix)
        ]
        return cls(
            plane,
            cls_.reshape(k),
            box,
            _csr(stack, k),
            np.array([p is not None for p in pix], bool).reshape(k),
        )


@dataclass(frozen=True, eq=False)
class GroundTruth:
    """Ground-truth targets of a stack of planes, as given (see the module docstring).

    Attributes:
        plane: int64 ``(G,)`` plane of each target.
        area: float64 ``(G,)`` its area in pixels (a mask's pixel count, a box's area).
        box: float64 ``(G, 4)`` ``(r0, c0, r1, c1)`` end-exclusive.
        classes: object ``(G,)`` class names.
        masks: the targets' pixels (flat stack indices; a box target may have none).
        has_mask: bool ``(G,)``: the target is its mask (mask IoU); else its box.
        crowd: the don't-care regions (:class:`Regions`).
        planes: number of planes ``N``.
        shape: ``(H, W)`` of the planes.
        box_only: bool ``(N,)`` planes whose ground truth is boxes only.
        centroid: float64 ``(G, 2)`` (row, col) pixel-index centroid (a box's centre).
        spacing: float64 ``(N, 2)`` pixel spacing (row, col) in metres, NaN if unknown.
        length_m: float64 ``(G,)`` declared lengths in metres (NaN where unknown).
        declared_area: float64 ``(G,)`` areas the annotations declare (COCO ``area``; NaN
            where unknown), used for COCO's area ranges.
        known_scr_db: float64 ``(G,)`` signal-to-clutter ratios in dB the data declare
            (a simulator's known value; NaN where unknown), or ``None``.
        scr_db: float64 ``(G,)`` signal-to-clutter ratios in dB measured on the image
            (:func:`torchsar.metrics.scr.target_scr_db`), or ``None`` (not measured).
        shadow: bool ``(N,)`` planes whose don't-care pixels are radar shadow, or ``None``
            (unknown: no plane's).
    """

    plane: np.ndarray
    area: np.ndarray
    box: np.ndarray
    classes: np.ndarray
    masks: ObjectMasks
    has_mask: np.ndarray
    crowd: Regions
    planes: int
    shape: tuple[int, int]
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

    @property
    def coco_area(self) -> np.ndarray:
        """The area COCO's area ranges read: the declared one where given, else
        :attr:`area`."""
        if self.declared_area is None:
            return self.area
        return np.where(np.isfinite(self.declared_area), self.declared_area, self.area)

    def pixels_of(self, k: int) -> np.ndarray:
        """Flat stack indices of target ``k``: its pixels, or its box rasterised."""
        own = self.masks.of(k)
        if own.size or self.has_mask[k]:
            return own
        h, w = self.shape
        return box_pixels(self.box[k], (h, w)) + int(self.plane[k]) * h * w

    def region_pixels(self, k: int) -> np.ndarray:
        """Flat stack indices of don't-care region ``k`` (its pixels, or its box
        rasterised)."""
        if self.crowd.has_mask[k]:
            return self.crowd.masks.of(k)
        h, w = self.shape
        return box_pixels(self.crowd.box[k], (h, w)) + int(self.crowd.plane[k]) * h * w

    @cached_property
    def ids(self) -> np.ndarray:
        """int64 ``(N, H, W)`` target ids ``k + 1`` painted in order (a later target wins
        where two overlap; boxes without pixels rasterised): a view for pixel-plane code."""
        h, w = self.shape
        out = np.zeros(self.planes * h * w, np.int64)
        for k in range(len(self)):
            out[self.pixels_of(k)] = k + 1
        return out.reshape(self.planes, h, w)

    @cached_property
    def ignore(self) -> np.ndarray:
        """bool ``(N, H, W)``: pixels of a don't-care region that belong to no target."""
        h, w = self.shape
        out = np.zeros(self.planes * h * w, bool)
        for k in range(len(self.crowd)):
            out[self.region_pixels(k)] = True
        return out.reshape(self.planes, h, w) & (self.ids == 0)

    @classmethod
    def build(
        cls,
        plane: np.ndarray,
        box: np.ndarray,
        *,
        planes: int,
        shape: tuple[int, int],
        classes: Sequence[str] | None = None,
        pixels: Sequence[np.ndarray | None] | None = None,
        crowd: Regions | None = None,
        box_only: np.ndarray | None = None,
        spacing: np.ndarray | None = None,
        length_m: np.ndarray | None = None,
        declared_area: np.ndarray | None = None,
        known_scr_db: np.ndarray | None = None,
        shadow: np.ndarray | None = None,
    ) -> GroundTruth:
        """Ground truth from its targets: plane, box ``(r0, c0, r1, c1)``, class (default
        ``"target"``) and pixels (flat in-plane indices; ``None``: a box target).

        Examples:
            >>> box = np.array([[0, 0, 2, 2], [1, 1, 3, 3.]])
            >>> gt = GroundTruth.build(np.array([0, 0]), box, planes=1, shape=(4, 4),
            ...                        pixels=[np.array([0, 1, 4, 5]), None])
            >>> gt.area.tolist(), gt.has_mask.tolist(), int(gt.ids[0, 1, 1])  # the box: last
            ([4.0, 4.0], [True, False], 2)
        """
        plane = np.asarray(plane, np.int64).reshape(-1)
        g = plane.size
        box = np.asarray(box, np.float64).reshape(g, 4)
        h, w = shape
        if pixels is None:  # box targets only: no list per target
            has, masks = np.zeros(g, bool), _no_pixels(g)
        else:
            pix = list(pixels)
            if len(pix) != g:
                raise ShapeError(f"pixels must hold one entry per target ({g}), got {len(pix)}")
            has = np.array([p is not None for p in pix], bool).reshape(g)
            stack = [
                None if p is None else np.asarray(p, np.int64) + plane[i] * h * w
                for i, p in enumerate(pix)
            ]
            masks = _csr(stack, g)
        counts = np.diff(masks.offsets).astype(np.float64)
        box_area = (box[:, 2] - box[:, 0]) * (box[:, 3] - box[:, 1])
        area = np.where(has, counts, box_area)
        centroid = 0.5 * (box[:, :2] + box[:, 2:]) - 0.5
        if has.any():
            owner = masks.owner()
            local = masks.pixels - plane[owner] * h * w
            sums = np.stack(
                [np.bincount(owner, weights=v, minlength=g) for v in (local // w, local % w)],
                axis=1,
            )
            mean = sums / np.maximum(counts, 1)[:, None]
            centroid = np.where((has & (counts > 0))[:, None], mean, centroid)
        cls_ = np.array(
            ["target"] * g if classes is None else [str(c) for c in classes], dtype=object
        ).reshape(g)
        nan = np.full(g, np.nan)
        return cls(
            plane,
            area,
            box,
            cls_,
            masks,
            has,
            Regions.none() if crowd is None else crowd,
            int(planes),
            (int(h), int(w)),
            np.zeros(int(planes), bool) if box_only is None else np.asarray(box_only, bool),
            centroid,
            np.full((int(planes), 2), np.nan) if spacing is None else np.asarray(spacing, float),
            nan if length_m is None else np.asarray(length_m, np.float64),
            nan.copy() if declared_area is None else np.asarray(declared_area, np.float64),
            None if known_scr_db is None else np.asarray(known_scr_db, np.float64),
            None,
            None if shadow is None else np.asarray(shadow, bool).reshape(int(planes)),
        )


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
    """:class:`GroundTruth` from instance-id planes ``(N, H, W)`` (targets that do not
    overlap: one id per pixel) and don't-care pixels (one region of every class per plane).

    Args:
        instances: integer ids per plane (0 = none; any positive ids). Floating ids are
            accepted when they are whole numbers.
        ignore: bool don't-care pixels, same shape (default none).
        classes: per plane, the class of local id ``k`` at position ``k - 1`` (default
            ``"target"``).
        boxes: per plane, the box of local id ``k`` at position ``k - 1`` (default: the
            bounding box of the id's pixels); required to be exact for box-only planes.
        box_only: bool per plane (default all False): its targets are boxes (box IoU), their
            pixels the painted boxes.
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

    Examples:
        >>> ids = np.zeros((1, 4, 4), int); ids[0, :2, :2] = 5; ids[0, 3, 3] = 2
        >>> gt = ground_truth(ids)
        >>> gt.area.tolist(), gt.box.tolist()  # ids in order: 2, then 5
        ([1.0, 4.0], [[3.0, 3.0, 4.0, 4.0], [0.0, 0.0, 2.0, 2.0]])
    """
    inst = check_ids(instances, "instances", ndim=3)
    if ignore is not None:
        check_same_shape(np.asarray(ignore), inst, "ignore", "instances")
    n_planes, h, w = inst.shape
    flat = inst.reshape(-1)
    idx = np.flatnonzero(flat)  # the labelled pixels: everything below works on them only
    top = int(flat.max(initial=0)) + 1
    key = (idx // (h * w)) * top + flat[idx].astype(np.int64)
    keys, inv = np.unique(key, return_inverse=True)  # planes in order, then local ids
    n = int(keys.size)
    plane, local = keys // top, keys % top
    order = np.argsort(inv, kind="stable")
    counts = np.bincount(inv, minlength=n)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    pix = idx[order]
    rows, cols = (pix % (h * w)) // w, pix % w
    box = np.zeros((n, 4))
    if n:
        starts = offsets[:-1]
        box[:, 0] = np.minimum.reduceat(rows, starts)
        box[:, 1] = np.minimum.reduceat(cols, starts)
        box[:, 2] = np.maximum.reduceat(rows, starts) + 1
        box[:, 3] = np.maximum.reduceat(cols, starts) + 1
    per = {
        "classes": classes,
        "boxes": boxes,
        "lengths": lengths,
        "areas": areas,
        "known": known_scr_db,
    }
    values = {k: [None] * n for k in per}
    for k in range(n):
        p, i = int(plane[k]), int(local[k]) - 1
        for name, given in per.items():
            if given is not None and i < len(given[p]):
                values[name][k] = given[p][i]
    for k, b in enumerate(values["boxes"]):
        if b is not None:
            box[k] = np.asarray(b, dtype=np.float64)
    bo = np.zeros(n_planes, bool) if box_only is None else np.asarray(box_only, bool)
    on_box = bo[plane] if n else np.zeros(0, bool)
    ig = np.zeros(inst.shape, bool) if ignore is None else np.asarray(ignore, bool)
    gt = GroundTruth.build(
        plane,
        box,
        planes=n_planes,
        shape=(h, w),
        classes=["target" if c is None else str(c) for c in values["classes"]],
        pixels=[pix[offsets[k] : offsets[k + 1]] - plane[k] * h * w for k in range(n)],
        crowd=Regions.from_planes(ig & (flat.reshape(inst.shape) == 0)),
        box_only=bo,
        spacing=spacing,
        length_m=np.array([np.nan if v is None else float(v) for v in values["lengths"]]),
        declared_area=np.array([np.nan if v is None else float(v) for v in values["areas"]]),
        known_scr_db=None
        if known_scr_db is None
        else np.array([np.nan if v is None else float(v) for v in values["known"]]),
        shadow=shadow,
    )
    if on_box.any():  # box-only planes: box IoU, box centres; their pixels stay (painted boxes)
        has = gt.has_mask & ~on_box
        centroid = gt.centroid.copy()
        centroid[on_box] = 0.5 * (gt.box[on_box, :2] + gt.box[on_box, 2:]) - 0.5
        area = np.where(on_box, np.diff(gt.masks.offsets), gt.area).astype(np.float64)
        object.__setattr__(gt, "has_mask", has)
        object.__setattr__(gt, "centroid", centroid)
        object.__setattr__(gt, "area", area)
    return gt
