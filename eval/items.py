"""Ground truth of one image as given (:class:`Targets`): what a dataset item carries and
what a training loop hands to :class:`~torchsar_eval.Evaluator`.

:class:`Item` is a dataset item typed: its image, its :class:`Targets` and its
:class:`ImageMeta`. Every target is its own object: a box ``(r0, c0, r1, c1)``
(end-exclusive, floats), a class, and, when it is a mask, its pixels (flat row-major
indices in the image); targets may overlap. Don't-care (crowd) regions are kept apart,
each a box or a mask, with the class it applies to (``None``: every class). Nothing is
painted into a plane, so a box target with box detections is scored without touching a
pixel.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from torchsar_eval.errors import EvalError

__all__ = ["ImageMeta", "Item", "Targets", "extent", "spacings"]


def _column(values, n: int, name: str, dtype=np.float64) -> np.ndarray:
    """A per-target column (NaN where unknown)."""
    if values is None:
        return np.full(n, np.nan)
    a = np.array([np.nan if v is None else v for v in values], dtype=dtype).reshape(-1)
    if a.size != n:
        raise EvalError(f"{name} must hold one value per target ({n}), got {a.size}")
    return a


def _pixels(values, n: int, name: str, size: int | None) -> tuple:
    """Per-target flat pixel arrays (``None``: a box)."""
    if values is None:
        return (None,) * n
    out = tuple(None if v is None else np.asarray(v, np.int64).reshape(-1) for v in values)
    if len(out) != n:
        raise EvalError(f"{name} must hold one entry per target ({n}), got {len(out)}")
    for v in out:
        if v is not None and v.size and (v.min() < 0 or (size is not None and v.max() >= size)):
            raise EvalError(f"{name} holds a pixel index outside the image")
    return out


def _boxes(boxes, name: str) -> np.ndarray:
    b = np.asarray(boxes, dtype=np.float64)
    if b.size == 0:
        return np.zeros((0, 4))
    if b.ndim != 2 or b.shape[1] != 4:
        raise EvalError(f"{name} must be (N, 4) boxes (r0, c0, r1, c1), got shape {b.shape}")
    if not np.isfinite(b).all() or (b[:, 2:] < b[:, :2]).any():
        raise EvalError(f"{name} must be finite boxes with r1 >= r0 and c1 >= c0")
    return b


@dataclass(frozen=True, eq=False)
class Targets:
    """The ground truth of one image, as given (see the module docstring).

    Attributes:
        boxes: float64 ``(N, 4)`` ``(r0, c0, r1, c1)``, end-exclusive.
        classes: one class name per target.
        pixels: per target its flat pixel indices (a mask), or ``None`` (a box target).
        areas: float64 ``(N,)`` areas the annotations declare (COCO ``area``; NaN: none).
        lengths_m: float64 ``(N,)`` lengths in metres (NaN: unknown).
        scr_db: float64 ``(N,)`` known signal-to-clutter ratios in dB (NaN: unknown).
        crowd_boxes: float64 ``(K, 4)`` don't-care regions' boxes.
        crowd_classes: the class each region applies to (``None``: every class).
        crowd_pixels: per region its pixels, or ``None`` (the region is its box).

    Examples:
        >>> t = Targets.build([[0, 0, 4, 4], [2, 2, 6, 6]], classes=["ship", "ship"])
        >>> len(t), t.pixels  # two overlapping boxes, kept apart
        (2, (None, None))
    """

    boxes: np.ndarray
    classes: tuple[str, ...]
    pixels: tuple = ()
    areas: np.ndarray = field(default_factory=lambda: np.zeros(0))
    lengths_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    scr_db: np.ndarray = field(default_factory=lambda: np.zeros(0))
    crowd_boxes: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    crowd_classes: tuple = ()
    crowd_pixels: tuple = ()

    def __len__(self) -> int:
        return int(self.boxes.shape[0])

    @classmethod
    def build(
        cls,
        boxes,
        *,
        classes: Sequence[str] | None = None,
        pixels: Sequence | None = None,
        areas: Sequence | None = None,
        lengths_m: Sequence | None = None,
        scr_db: Sequence | None = None,
        crowd_boxes=None,
        crowd_classes: Sequence[str | None] | None = None,
        crowd_pixels: Sequence | None = None,
        size: int | None = None,
    ) -> Targets:
        """Checked :class:`Targets` (``size``: the image's pixel count, to check pixel
        indices; every argument after ``boxes`` optional).

        Raises:
            EvalError: a column of another length than the boxes, a bad box or pixel index.
        """
        b = _boxes(boxes, "boxes")
        n = b.shape[0]
        names = ("target",) * n if classes is None else tuple(str(c) for c in classes)
        if len(names) != n:
            raise EvalError(f"classes must hold one name per target ({n}), got {len(names)}")
        cb = _boxes(np.zeros((0, 4)) if crowd_boxes is None else crowd_boxes, "crowd_boxes")
        k = cb.shape[0]
        cc = (
            (None,) * k
            if crowd_classes is None
            else tuple(None if c is None else str(c) for c in crowd_classes)
        )
        if len(cc) != k:
            raise EvalError(f"crowd_classes must hold one entry per region ({k}), got {len(cc)}")
        return cls(
            b,
            names,
            _pixels(pixels, n, "pixels", size),
            _column(areas, n, "areas"),
            _column(lengths_m, n, "lengths_m"),
            _column(scr_db, n, "scr_db"),
            cb,
            cc,
            _pixels(crowd_pixels, k, "crowd_pixels", size),
        )

    @property
    def has_masks(self) -> bool:
        """Whether some target is a mask."""
        return any(p is not None for p in self.pixels)


@dataclass(frozen=True)
class ImageMeta:
    """What the scorer needs to know about one image besides its pixels and ground truth.

    Attributes:
        name: the image's name (its key in the tables and its bootstrap unit).
        index: its order in the dataset (ties in score are ranked by it, as pycocotools
            ranks them by image id; unique per image). ``None``: the order it was added in.
        shape: ``(H, W)`` (``None``: from the image, the masks, or the boxes' extent).
        cls: an image-level class (breakdown ``image_class``), or ``None``.
        group: a group of images (breakdown ``group``; the bootstrap unit with
            ``bootstrap_unit="group"``), or ``None``.
        pixel_spacing: ``(row, col)`` metres per pixel (false alarms per km²), or ``None``.
    """

    name: str
    index: int | None = None
    shape: tuple[int, int] | None = None
    cls: str | None = None
    group: str | None = None
    pixel_spacing: tuple[float, float] | None = None

    def as_meta(self) -> dict:
        """The harness's per-image meta dict."""
        out = {
            "name": self.name,
            "class": self.cls,
            "group": self.group,
            "pixel_spacing": self.pixel_spacing,
        }
        if self.index is not None:
            out["index"] = int(self.index)
        return out


@dataclass(frozen=True)
class Item:
    """One image of a dataset, typed: its intensity image ``(C, H, W)`` (or ``None`` when
    only the ground truth is scored), its ground truth as given and its facts. A torch
    ``Dataset`` yielding these is a dataset :func:`~torchsar_eval.evaluate` scores; a
    training loop hands them to :meth:`~torchsar_eval.Evaluator.update`.

    Examples:
        >>> it = Item(None, Targets.build([[2, 2, 6, 6]]), ImageMeta("a", index=0, shape=(8, 8)))
        >>> sorted(it.as_dict())
        ['ignore', 'image', 'instances', 'mask', 'meta', 'targets']
    """

    image: object
    targets: Targets
    meta: ImageMeta

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``: the meta's, else the image's, else the ground truth's extent."""
        if self.meta.shape is not None:
            return (int(self.meta.shape[0]), int(self.meta.shape[1]))
        if self.image is not None:
            return (int(self.image.shape[-2]), int(self.image.shape[-1]))
        return extent(self.targets)

    def as_dict(self) -> dict:
        """The harness's item: the image (zeros when ``None``), the targets painted into the
        ``mask``, ``instances`` and ``ignore`` planes (for pixel metrics and pictures; the
        scoring reads ``targets``, as given) and the meta."""
        # torch and the library only to paint planes: the typed items are read without them
        import torch

        from torchsar.metrics.truth import box_pixels

        h, w = self.shape
        t = self.targets
        inst = np.zeros(h * w, np.int32)
        ignore = np.zeros(h * w, bool)
        for k in range(len(t)):
            p = t.pixels[k] if t.pixels[k] is not None else box_pixels(t.boxes[k], (h, w))
            inst[p] = k + 1
        for k in range(len(t.crowd_classes)):
            p = t.crowd_pixels[k]
            ignore[p if p is not None else box_pixels(t.crowd_boxes[k], (h, w))] = True
        image = (
            torch.zeros(1, h, w)
            if self.image is None
            else torch.as_tensor(self.image, dtype=torch.float32)
        )
        image = image[None] if image.ndim == 2 else image
        meta = self.meta.as_meta()
        meta.update(
            classes=list(t.classes),
            boxes=[tuple(b) for b in t.boxes.tolist()],
            box_source="annotation",
            gt="box" if None in t.pixels else "mask",
        )
        planes = {
            "mask": torch.from_numpy((inst > 0).reshape(1, h, w)),
            "instances": torch.from_numpy(inst.reshape(1, h, w)),
            "ignore": torch.from_numpy((ignore & (inst == 0)).reshape(1, h, w)),
        }
        c = image.shape[0]
        planes = {k: v.expand(c, h, w).clone() for k, v in planes.items()}
        return {"image": image, **planes, "meta": meta, "targets": t}


def extent(targets: Targets) -> tuple[int, int]:
    """The smallest ``(H, W)`` holding every box of ``targets`` (at least 1 x 1)."""
    boxes = np.concatenate([targets.boxes, targets.crowd_boxes]).reshape(-1, 4)
    if boxes.size == 0:
        return (1, 1)
    return (max(int(np.ceil(boxes[:, 2].max())), 1), max(int(np.ceil(boxes[:, 3].max())), 1))


def spacings(metas: Sequence[dict]) -> np.ndarray:
    """float64 ``(N, 2)``: each image's ``pixel_spacing`` (row, col) in metres from its meta
    dict, NaN where it has none.

    Examples:
        >>> spacings([{"pixel_spacing": (0.3, 0.3)}, {}]).tolist()
        [[0.3, 0.3], [nan, nan]]
    """
    nan = (np.nan, np.nan)
    rows = [nan if m.get("pixel_spacing") is None else m["pixel_spacing"][:2] for m in metas]
    return np.array(rows, np.float64).reshape(len(rows), 2)
