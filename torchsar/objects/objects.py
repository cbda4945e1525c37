"""Scored objects of a batch: what every detector's output becomes before matching.

An :class:`Objects` holds the objects of a stack of planes (``(B, C, H, W)`` flattened to
``B * C`` planes) with one score each. Three geometries:

- ``"mask"``: pixel masks. Objects that never overlap (the discrimination stage's
  connected components, a region CFAR's labels) keep a label map ``labels`` (one id per
  pixel); objects that may overlap (a CNN's instance masks, saved predictions) keep
  ``masks``, a compressed list of each object's pixels.
- ``"box"``: boxes only (a box detector, COCO ``bbox`` results): matched by box IoU.
- ``"point"``: points only (a centroid detector, xView3-style CSV): matched by the
  prescreening or the distance rule; no IoU, so no AP by IoU.

``score`` is what the detector says, in any range (a CFAR ratio, a probability, a logit).
``threshold`` is the detector's operating threshold on it (objects scoring above it are
the detector's declared detections); ``None`` declares none: every object counts at the
operating point. The discrimination stage's objects have ``threshold == 1`` (scores are
statistic / design threshold).

Build one with :func:`~torchsar.objects.discriminate` or with the constructors
:meth:`Objects.from_labels`, :meth:`Objects.from_masks`, :meth:`Objects.from_boxes`,
:meth:`Objects.from_points` and :meth:`Objects.from_torchvision`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from torchsar._checks import check_choice
from torchsar.errors import InputValueError, OptionError, ShapeError
from torchsar.objects.properties import measure_pixels

__all__ = ["GEOMETRIES", "ObjectMasks", "Objects"]

GEOMETRIES = ("mask", "box", "point")
BOX_FORMATS = ("rc", "xyxy", "xywh")


_MAX_AREA = 1 << 62
"""The largest area (pixels) a box object records: larger ones saturate (an int64 cannot
hold the area of a finite box of 1e300 pixels a side)."""


@dataclass(frozen=True)
class ObjectMasks:
    """The pixels of possibly overlapping objects, compressed row by row (CSR).

    Attributes:
        offsets: int64 ``(M + 1,)``; object ``k`` owns ``pixels[offsets[k]:offsets[k + 1]]``.
        pixels: int64 ``(P,)`` flat indices into the ``(N, H, W)`` stack, object by object.
    """

    offsets: np.ndarray
    pixels: np.ndarray

    def owner(self) -> np.ndarray:
        """The object index of each entry of :attr:`pixels`."""
        return np.repeat(np.arange(self.offsets.size - 1), np.diff(self.offsets))

    def of(self, k: int) -> np.ndarray:
        """Flat stack indices of object ``k``'s pixels."""
        return self.pixels[self.offsets[k] : self.offsets[k + 1]]


@dataclass(frozen=True)
class Objects:
    """Scored objects of a batch ``(B, C, H, W)``; each ``(b, c)`` plane is one image.

    Attributes:
        labels: int32 ``(B * C, H, W)`` object ids, unique across the batch (0 = none);
            object ``k`` (0-based in the arrays below) has id ``k + 1``. ``None`` when the
            objects may overlap (see ``masks``) or have no masks.
        plane: int64 ``(M,)`` plane index ``b * C + c`` of each object.
        score: float64 ``(M,)`` the detector's score (any range; larger = more target-like).
        area: int64 ``(M,)`` pixels (a box's area for boxes, 0 for points).
        box: float64 ``(M, 4)`` ``(r0, c0, r1, c1)``, end-exclusive.
        centroid: float64 ``(M, 2)`` (row, col) in pixel-index coordinates.
        length, width: float64 ``(M,)`` major / minor axis lengths in pixels (a box's longer
            and shorter side; 0 for points).
        planes: number of planes ``B * C``.
        shape: ``(H, W)`` of every plane.
        masks: the objects' pixels when they may overlap (``labels`` is then ``None``).
        geometry: ``"mask"``, ``"box"`` or ``"point"``.
        threshold: the operating threshold on ``score`` (``None``: every object counts).
        classes: object array ``(M,)`` of class names, or ``None`` (class-agnostic).
        length_m: float64 ``(M,)`` lengths in metres declared by the detector (NaN where
            unknown), or ``None``.
        declared_area: float64 ``(M,)`` areas the source declares (NaN where none), or
            ``None``: what COCO's area ranges read instead of :attr:`area` (``pycocotools``
            reads a results entry's ``bbox`` ``w * h`` when it has one, even for masks).
    """

    labels: np.ndarray | None
    plane: np.ndarray
    score: np.ndarray
    area: np.ndarray
    box: np.ndarray
    centroid: np.ndarray
    length: np.ndarray
    width: np.ndarray
    planes: int
    shape: tuple[int, int]
    masks: ObjectMasks | None = None
    geometry: str = "mask"
    threshold: float | None = 1.0
    classes: np.ndarray | None = None
    length_m: np.ndarray | None = None
    declared_area: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.score.shape[0])

    def in_plane(self, p: int) -> np.ndarray:
        """Indices (0-based) of the objects of plane ``p``."""
        return np.flatnonzero(self.plane == p)

    @property
    def has_masks(self) -> bool:
        """Whether the objects carry pixel masks (mask IoU and pixel metrics apply)."""
        return self.geometry == "mask"

    def pixel_lists(self) -> tuple[np.ndarray, np.ndarray]:
        """``(owner, flat index)`` of every object pixel: the object index and the flat
        index into the ``(N, H, W)`` stack (ascending by object for ``masks``)."""
        if self.labels is not None:
            known = self.__dict__.get("_pixel_lists")
            if known is None:
                flat = self.labels.reshape(-1)
                idx = np.flatnonzero(flat)
                known = (flat[idx].astype(np.int64) - 1, idx)
                object.__setattr__(self, "_pixel_lists", known)  # a label map never changes
            return known
        if self.masks is not None:
            return self.masks.owner(), self.masks.pixels
        return np.zeros(0, np.int64), np.zeros(0, np.int64)

    def with_pixel_lists(self, owner: np.ndarray, idx: np.ndarray) -> Objects:
        """These objects, knowing their :meth:`pixel_lists` (of their label map: what a
        constructor that has them at hand passes on, so no one searches the map again)."""
        if self.labels is not None:
            object.__setattr__(self, "_pixel_lists", (owner, idx))
        return self

    def mask_of(self, k: int) -> np.ndarray:
        """Bool ``(H, W)`` mask of object ``k`` (its box or point for other geometries)."""
        h, w = self.shape
        p = int(self.plane[k])
        if self.labels is not None:
            return self.labels[p] == k + 1
        out = np.zeros(h * w, bool)
        if self.masks is not None:
            out[self.masks.of(k) - p * h * w] = True
            return out.reshape(h, w)
        r0, c0, r1, c1 = (math.floor(v + 0.5) for v in self.box[k])
        out = out.reshape(h, w)
        out[max(r0, 0) : max(r1, r0 + 1), max(c0, 0) : max(c1, c0 + 1)] = True
        return out

    def with_threshold(self, threshold: float | None) -> Objects:
        """The same objects with another operating threshold."""
        return replace(self, threshold=_threshold(threshold))

    def with_declared_area(self, area: np.ndarray | None) -> Objects:
        """The same objects with the areas their source declares (see
        :attr:`declared_area`; NaN where none).

        Examples:
            >>> o = Objects.from_points(np.zeros((1, 2)), np.array([1.0]), shape=(4, 4))
            >>> o.with_declared_area(np.array([6.0])).declared_area.tolist()
            [6.0]
        """
        if area is None:
            return replace(self, declared_area=None)
        a = np.asarray(area, dtype=np.float64).reshape(-1)
        if a.shape != (len(self),):
            raise ShapeError(
                f"declared_area must have one entry per object ({len(self)}), got {a.shape}"
            )
        return replace(self, declared_area=a)

    # -- constructors ------------------------------------------------------------------------

    @classmethod
    def empty(cls, planes: int, shape: tuple[int, int], *, geometry: str = "mask") -> Objects:
        """No objects in ``planes`` planes of ``shape``."""
        check_choice(geometry, "geometry", GEOMETRIES)
        h, w = _shape(shape)
        labels = np.zeros((planes, h, w), np.int32) if geometry == "mask" else None
        return _build(labels, None, _props_none(0), planes, (h, w), geometry, None, None, None)

    @classmethod
    def from_labels(
        cls,
        labels: np.ndarray,
        score_map: np.ndarray,
        *,
        threshold: float | None = 1.0,
    ) -> Objects:
        """Objects from a label map: every nonzero id of a plane is one object, scored by
        the maximum of ``score_map`` over its pixels.

        Args:
            labels: int ``(N, H, W)`` ids per plane (0 = none; ids need not be consecutive).
            score_map: float ``(N, H, W)`` per-pixel score.
            threshold: the operating threshold on the scores.

        Examples:
            >>> lab = np.zeros((1, 4, 4), int); lab[0, :2, :2] = 7; lab[0, 3, 3] = 2
            >>> o = Objects.from_labels(lab, np.arange(16.0).reshape(1, 4, 4))
            >>> o.area.tolist(), o.score.tolist()
            ([1, 4], [15.0, 5.0])
        """
        lab = np.asarray(labels)
        if lab.ndim != 3 or not np.issubdtype(lab.dtype, np.integer):
            raise ShapeError(
                f"labels must be an integer array (N, H, W), got {lab.dtype} {lab.shape}"
            )
        smap = np.asarray(score_map, dtype=np.float64)
        if smap.shape != lab.shape:
            raise ShapeError(
                f"score_map must have the shape of labels {lab.shape}, got {smap.shape}"
            )
        flat = lab.reshape(-1)
        idx = np.flatnonzero(flat > 0)  # the labelled pixels (the rest stays 0)
        return cls.from_label_pixels(
            flat[idx], idx, smap.reshape(-1)[idx], lab.shape, threshold=threshold
        )

    @classmethod
    def from_label_pixels(
        cls,
        local: np.ndarray,
        idx: np.ndarray,
        values: np.ndarray,
        shape: tuple[int, int, int],
        *,
        threshold: float | None = 1.0,
    ) -> Objects:
        """:meth:`from_labels` from the labelled pixels only: their flat indices ``idx``
        (ascending) into a stack of ``shape`` ``(N, H, W)``, their positive ids ``local``
        (per plane; need not be consecutive) and their scores ``values``.

        Examples:
            >>> o = Objects.from_label_pixels(np.array([7, 7, 2]), np.array([0, 1, 15]),
            ...                               np.array([1.0, 3.0, 2.0]), (1, 4, 4))
            >>> o.area.tolist(), o.score.tolist()
            ([1, 2], [2.0, 3.0])
        """
        n_planes, h, w = shape
        local = np.asarray(local).astype(np.int64)
        key = local + (int(local.max(initial=0)) + 1) * (idx // (h * w))
        used = np.unique(key)
        new = np.searchsorted(used, key) + 1
        ids = np.zeros(n_planes * h * w, np.int32)
        ids[idx] = new
        props = measure_pixels(new, idx, (h, w), used.size, np.asarray(values, np.float64))
        _check_scores(props["score"], "score_map")
        built = _build(
            ids.reshape(shape), None, props, n_planes, (h, w), "mask", threshold, None, None
        )
        return built.with_pixel_lists(new - 1, idx)

    @classmethod
    def from_masks(
        cls,
        masks: np.ndarray | Sequence[np.ndarray],
        scores: np.ndarray | Sequence[np.ndarray],
        *,
        plane: np.ndarray | None = None,
        planes: int | None = None,
        threshold: float | None = None,
        classes: Sequence[str] | None = None,
    ) -> Objects:
        """Objects from (possibly overlapping) bool masks.

        Args:
            masks: bool ``(M, H, W)`` with ``plane`` giving each mask's plane, or one bool
                ``(M_p, H, W)`` array per plane.
            scores: ``(M,)`` (or one ``(M_p,)`` array per plane).
            plane: int ``(M,)`` plane of each mask (when ``masks`` is one array; default 0).
            planes: number of planes (default: as many as given or referenced).
            threshold: the operating threshold on the scores (``None``: every object counts).
            classes: ``(M,)`` class names (default: class-agnostic).

        Examples:
            >>> m = np.zeros((2, 4, 4), bool); m[0, :2, :2] = True; m[1, 1:3, 1:3] = True
            >>> o = Objects.from_masks(m, [0.9, 0.4])  # the two masks overlap
            >>> o.area.tolist(), o.box[1].tolist()
            ([4, 4], [1.0, 1.0, 3.0, 3.0])
        """
        arr, scores, plane, planes = _per_plane(masks, scores, plane, planes, "masks", 3)
        arr = arr.astype(bool, copy=False)
        m, h, w = arr.shape
        pixels = [np.flatnonzero(a) for a in arr.reshape(m, h * w)]
        return cls.from_pixel_lists(
            pixels,
            scores,
            shape=(h, w),
            plane=plane,
            planes=planes,
            threshold=threshold,
            classes=classes,
        )

    @classmethod
    def from_pixel_lists(
        cls,
        pixels: Sequence[np.ndarray],
        scores: np.ndarray,
        *,
        shape: tuple[int, int],
        plane: np.ndarray | None = None,
        planes: int | None = None,
        threshold: float | None = None,
        classes: Sequence[str] | None = None,
    ) -> Objects:
        """Objects from the flat pixel indices (``row * W + col``) of each object's mask in
        its plane: :meth:`from_masks` without dense masks (e.g. decoded run lengths).

        Examples:
            >>> o = Objects.from_pixel_lists([np.array([0, 1, 5])], np.array([1.0]), shape=(4, 4))
            >>> o.area.tolist(), o.box.tolist()
            ([3], [[0.0, 0.0, 2.0, 2.0]])
        """
        m = len(pixels)
        counts = np.array([len(p) for p in pixels], dtype=np.int64)
        local = (
            np.concatenate([np.asarray(p, np.int64) for p in pixels])
            if m
            else np.zeros(0, np.int64)
        )
        return cls.from_pixels(
            np.repeat(np.arange(m), counts),
            local,
            scores,
            shape=shape,
            plane=plane,
            planes=planes,
            threshold=threshold,
            classes=classes,
        )

    @classmethod
    def from_pixels(
        cls,
        owner: np.ndarray,
        pixels: np.ndarray,
        scores: np.ndarray,
        *,
        shape: tuple[int, int],
        plane: np.ndarray | None = None,
        planes: int | None = None,
        threshold: float | None = None,
        classes: Sequence[str] | None = None,
    ) -> Objects:
        """:meth:`from_pixel_lists` with the pixels of every object in one array:
        ``pixels[i]`` (flat index in its plane) belongs to object ``owner[i]`` (objects in
        order: ``owner`` non-decreasing).

        Examples:
            >>> o = Objects.from_pixels(np.array([0, 0, 1]), np.array([0, 1, 9]),
            ...                         np.array([0.5, 0.7]), shape=(4, 4))
            >>> o.area.tolist(), o.centroid.tolist()
            ([2, 1], [[0.0, 0.5], [2.0, 1.0]])
        """
        h, w = _shape(shape)
        scores = np.asarray(scores, dtype=np.float64).reshape(-1)
        m = scores.size
        owner = np.asarray(owner, np.int64).reshape(-1)
        local = np.asarray(pixels, np.int64).reshape(-1)
        if owner.shape != local.shape or (
            owner.size and (owner.min() < 0 or owner.max() >= m or (np.diff(owner) < 0).any())
        ):
            raise ShapeError(f"owner must give each pixel its object in 0..{m - 1} in order")
        plane = np.zeros(m, np.int64) if plane is None else np.asarray(plane, np.int64)
        _, scores, plane, planes = _per_plane(np.zeros((m, 0)), scores, plane, planes, "pixels", 2)
        if local.size and (local.min() < 0 or local.max() >= h * w):
            raise InputValueError(f"pixel indices must lie in [0, H*W={h * w})")
        counts = np.bincount(owner, minlength=m)
        flat = plane[owner] * (h * w) + local
        offsets = np.concatenate([[0], np.cumsum(counts)])
        props = measure_pixels(owner + 1, flat, (h, w), m, scores[owner])
        props["plane"], props["score"] = plane, scores
        props["box"][props["area"] == 0] = 0.0  # an empty mask has no extent
        masks_ = ObjectMasks(offsets.astype(np.int64), flat.astype(np.int64))
        return _build(
            None, masks_, props, planes, (h, w), "mask", threshold, _classes(classes, m), None
        )

    @classmethod
    def from_boxes(
        cls,
        boxes: np.ndarray | Sequence[np.ndarray],
        scores: np.ndarray | Sequence[np.ndarray],
        *,
        shape: tuple[int, int],
        plane: np.ndarray | None = None,
        planes: int | None = None,
        box_format: str = "rc",
        threshold: float | None = None,
        classes: Sequence[str] | None = None,
    ) -> Objects:
        """Objects from boxes (matched by box IoU; no pixel masks).

        Args:
            boxes: ``(M, 4)`` (with ``plane``) or one ``(M_p, 4)`` array per plane, in
                ``box_format``: ``"rc"`` = ``(r0, c0, r1, c1)`` end-exclusive (torchsar's),
                ``"xyxy"`` = ``(x0, y0, x1, y1)`` (torchvision), ``"xywh"`` (COCO).
            scores: ``(M,)`` (or one array per plane).
            shape: ``(H, W)`` of the planes.
            plane, planes, threshold, classes: as in :meth:`from_masks`.

        Examples:
            >>> o = Objects.from_boxes([np.array([[10, 20, 30, 40.]])], [np.array([0.8])],
            ...                        shape=(64, 64), box_format="xyxy")
            >>> o.box.tolist(), o.centroid.tolist()
            ([[20.0, 10.0, 40.0, 30.0]], [[29.5, 19.5]])
        """
        check_choice(box_format, "box_format", BOX_FORMATS)
        arr, scores, plane, planes = _per_plane(boxes, scores, plane, planes, "boxes", 2)
        if arr.shape[-1] != 4:
            raise ShapeError(f"boxes must have shape (M, 4), got {arr.shape}")
        box = _to_rc(arr.astype(np.float64), box_format)
        if not np.isfinite(box).all() or (box[:, 2:] < box[:, :2]).any():
            raise InputValueError(f"boxes must be finite with r1 >= r0 and c1 >= c0 ({box_format})")
        hh, ww = box[:, 2] - box[:, 0], box[:, 3] - box[:, 1]
        with np.errstate(over="ignore"):  # a finite box of 1e300 px: its area saturates
            area = np.minimum(np.rint(hh * ww), float(_MAX_AREA)).astype(np.int64)
        props = {
            "plane": plane,
            "score": scores,
            "area": area,
            "box": box,
            "centroid": 0.5 * (box[:, :2] + box[:, 2:]) - 0.5,
            "length": np.maximum(hh, ww),
            "width": np.minimum(hh, ww),
        }
        return _build(
            None,
            None,
            props,
            planes,
            _shape(shape),
            "box",
            threshold,
            _classes(classes, len(scores)),
            None,
        )

    @classmethod
    def from_points(
        cls,
        points: np.ndarray | Sequence[np.ndarray],
        scores: np.ndarray | Sequence[np.ndarray],
        *,
        shape: tuple[int, int],
        plane: np.ndarray | None = None,
        planes: int | None = None,
        threshold: float | None = None,
        length_m: np.ndarray | None = None,
        classes: Sequence[str] | None = None,
    ) -> Objects:
        """Objects that are points ``(row, col)`` in pixel-index coordinates (matched by the
        centroid or the distance rule).

        Args:
            points: ``(M, 2)`` (with ``plane``) or one ``(M_p, 2)`` array per plane.
            scores: ``(M,)`` (or one array per plane).
            shape: ``(H, W)`` of the planes.
            length_m: ``(M,)`` object lengths in metres (NaN where unknown), for the length
                estimation score.
            plane, planes, threshold, classes: as in :meth:`from_masks`.

        Examples:
            >>> o = Objects.from_points(np.array([[5.0, 7.0]]), np.array([2.5]), shape=(16, 16))
            >>> o.centroid.tolist(), o.box.tolist(), o.geometry
            ([[5.0, 7.0]], [[5.5, 7.5, 5.5, 7.5]], 'point')
        """
        arr, scores, plane, planes = _per_plane(points, scores, plane, planes, "points", 2)
        if arr.shape[-1] != 2:
            raise ShapeError(f"points must have shape (M, 2), got {arr.shape}")
        pts = arr.astype(np.float64)
        if not np.isfinite(pts).all():
            raise InputValueError("points must be finite (row, col) coordinates")
        m = len(scores)
        props = {
            "plane": plane,
            "score": scores,
            "area": np.zeros(m, np.int64),
            "box": np.concatenate([pts + 0.5, pts + 0.5], axis=1),
            "centroid": pts,
            "length": np.zeros(m),
            "width": np.zeros(m),
        }
        lengths = None
        if length_m is not None:
            lengths = np.asarray(length_m, dtype=np.float64).reshape(-1)
            if lengths.shape != (m,):
                raise ShapeError(
                    f"length_m must have one value per point ({m}), got {lengths.shape}"
                )
        return _build(
            None,
            None,
            props,
            planes,
            _shape(shape),
            "point",
            threshold,
            _classes(classes, m),
            lengths,
        )

    @classmethod
    def from_torchvision(
        cls,
        outputs: Sequence[dict],
        *,
        shape: tuple[int, int],
        threshold: float | None = None,
        mask_threshold: float = 0.5,
    ) -> Objects:
        """Objects from torchvision detection outputs, one dict per image: ``boxes``
        ``(M, 4)`` xyxy, ``scores`` ``(M,)``, optional ``masks`` ``(M, 1, H, W)``
        (probabilities, cut at ``mask_threshold``) and ``labels`` (class ids, kept as names).

        Examples:
            >>> out = [{"boxes": torch.tensor([[1.0, 2, 5, 6]]), "scores": torch.tensor([0.7])}]
            >>> Objects.from_torchvision(out, shape=(8, 8)).box.tolist()
            [[2.0, 1.0, 6.0, 5.0]]
        """

        def arr(d: dict, k: str) -> np.ndarray:
            v = d[k]
            return v.detach().cpu().numpy() if hasattr(v, "detach") else np.asarray(v)

        scores = [arr(d, "scores").astype(np.float64) for d in outputs]
        classes = None
        if outputs and all("labels" in d for d in outputs):
            classes = [str(c) for d in outputs for c in arr(d, "labels").tolist()]
        if outputs and all("masks" in d for d in outputs):
            masks = [arr(d, "masks").reshape(-1, *shape) > mask_threshold for d in outputs]
            return cls.from_masks(
                masks, scores, planes=len(outputs), threshold=threshold, classes=classes
            )
        boxes = [arr(d, "boxes").reshape(-1, 4) for d in outputs]
        return cls.from_boxes(
            boxes,
            scores,
            shape=shape,
            box_format="xyxy",
            planes=len(outputs),
            threshold=threshold,
            classes=classes,
        )


# -- helpers ---------------------------------------------------------------------------------


def _shape(shape: object) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in shape)  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise OptionError(f"shape must be (H, W), got {shape!r}") from None
    if h < 1 or w < 1:
        raise OptionError(f"shape must be (H, W) with positive sides, got {shape!r}")
    return h, w


def _threshold(threshold: object) -> float | None:
    if threshold is None:
        return None
    if isinstance(threshold, bool) or not isinstance(threshold, int | float | np.floating):
        raise OptionError(f"threshold must be a number or None, got {threshold!r}")
    if math.isnan(threshold):
        raise OptionError("threshold must not be NaN")
    return float(threshold)


def _check_scores(scores: np.ndarray, name: str) -> None:
    if np.isnan(scores).any():
        raise InputValueError(f"{name} must not hold NaN values")


def _per_plane(items, scores, plane, planes, name: str, ndim: int):
    """Items and scores as one array each with a plane per item; accepts one array per plane."""
    if isinstance(items, list | tuple) and (len(items) == 0 or np.ndim(items[0]) == ndim):
        if not isinstance(scores, list | tuple) or len(scores) != len(items):
            raise ShapeError(
                f"with one {name} array per plane, scores must be a list of the "
                f"same length ({len(items)})"
            )
        counts = [len(np.asarray(s).reshape(-1)) for s in scores]
        plane = np.repeat(np.arange(len(items)), counts)
        planes = len(items) if planes is None else planes
        parts = [np.asarray(a) for a in items]
        tail = parts[0].shape[1:] if parts and parts[0].ndim == ndim else ()
        arr = (
            np.concatenate([a.reshape(-1, *a.shape[1:]) for a in parts])
            if parts and sum(counts)
            else np.zeros((0, *tail))
        )
        scores = (
            np.concatenate([np.asarray(s, np.float64).reshape(-1) for s in scores])
            if (scores)
            else np.zeros(0)
        )
    else:
        arr = np.asarray(items)
        scores = np.asarray(scores, dtype=np.float64).reshape(-1)
        plane = np.zeros(len(scores), np.int64) if plane is None else np.asarray(plane)
    if arr.ndim != ndim or arr.shape[0] != scores.shape[0]:
        raise ShapeError(
            f"{name} must hold one entry per score ({scores.shape[0]}), got shape {arr.shape}"
        )
    plane = plane.astype(np.int64).reshape(-1)
    if plane.shape != scores.shape:
        raise ShapeError(f"plane must have one entry per score ({scores.shape[0]})")
    n = int(plane.max(initial=-1)) + 1
    planes = n if planes is None else int(planes)
    if (plane < 0).any() or n > planes:
        raise OptionError(f"plane indices must lie in [0, planes={planes}), got max {n - 1}")
    _check_scores(scores, "scores")
    return arr, scores, plane, planes


def _to_rc(box: np.ndarray, fmt: str) -> np.ndarray:
    if fmt == "rc":
        return box.reshape(-1, 4)
    x0, y0, a, b = box.reshape(-1, 4).T
    x1, y1 = (a, b) if fmt == "xyxy" else (x0 + a, y0 + b)
    return np.stack([y0, x0, y1, x1], axis=1)


def _classes(classes, m: int) -> np.ndarray | None:
    if classes is None:
        return None
    out = np.array([str(c) for c in classes], dtype=object)
    if out.shape != (m,):
        raise ShapeError(f"classes must have one entry per object ({m}), got {out.shape}")
    return out


def _props_none(m: int) -> dict[str, np.ndarray]:
    return {
        "plane": np.zeros(m, np.int64),
        "score": np.zeros(m),
        "area": np.zeros(m, np.int64),
        "box": np.zeros((m, 4)),
        "centroid": np.zeros((m, 2)),
        "length": np.zeros(m),
        "width": np.zeros(m),
    }


def _build(labels, masks, props, planes, shape, geometry, threshold, classes, length_m):
    return Objects(
        labels=labels,
        plane=props["plane"].astype(np.int64),
        score=props["score"].astype(np.float64),
        area=props["area"].astype(np.int64),
        box=props["box"].astype(np.float64).reshape(-1, 4),
        centroid=props["centroid"].astype(np.float64).reshape(-1, 2),
        length=props["length"].astype(np.float64),
        width=props["width"].astype(np.float64),
        planes=int(planes),
        shape=shape,
        masks=masks,
        geometry=geometry,
        threshold=_threshold(threshold),
        classes=classes,
        length_m=length_m,
    )
