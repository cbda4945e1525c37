"""Datasets whose ground truth is an annotation file: ``coco:FILE.json`` and ``voc:DIR``.

Every item carries its ground truth as given (:class:`~torchsar_eval.items.Targets`): each
annotation its own target (its segmentation decoded to pixels, else its box), overlapping
ones as they are; COCO crowd regions and VOC ``difficult`` objects are don't-care regions
of their own class. The pixel planes of the item (``mask``, ``instances``, ``ignore``) are
the targets painted in annotation order, for pixel-level metrics and pictures only.

The images need not exist when nothing reads their pixels: saved predictions are scored
from the annotation file alone (sizes from the file), and an item whose image is missing
fails only when its pixels are read.

An image named by an annotation file must lie inside the image folder (``images=DIR``;
by default the COCO file's folder, or VOC's ``JPEGImages`` / the XML's folder): a name
with ``..``, an absolute path or a symbolic link that resolves outside it is refused, so an
annotation file cannot make the run read (and record in its manifest) files elsewhere on the
machine. ``outside=allow`` reads such images anyway.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from torchsar.io import (
    FileFormatError,
    raster_shape,
    read_coco_table,
    read_voc,
)
from torchsar.io.coco import CocoAnnotation, annotation_pixels
from torchsar.metrics.truth import GroundTruth, Regions
from torchsar_eval.datasets.base import FileDataset, make_item, require_dir, walk_files
from torchsar_eval.datasets.images import read_samples
from torchsar_eval.datasets.spec import DEFAULT_MAX_PIXELS, DatasetSpec
from torchsar_eval.errors import EvalError
from torchsar_eval.items import Targets, spacings

__all__ = ["ANNOTATED_OPTIONS", "AnnotatedDataset", "coco_from_spec", "voc_from_spec"]

ANNOTATED_OPTIONS = ("images", "type", "spacing", "max_pixels", "outside")
OUTSIDE = ("refuse", "allow")


@dataclass(frozen=True, eq=False)
class ObjectColumns:
    """Every object of an annotated dataset, one row each, grouped by image: image ``i``'s
    objects are rows ``start[i]:start[i + 1]`` (in annotation order).

    Attributes:
        start: int64 ``(N + 1,)`` row offsets per image.
        box: float64 ``(M, 4)`` ``(r0, c0, r1, c1)``.
        cls: object ``(M,)`` class names.
        ignore: bool ``(M,)`` don't-care (COCO crowd, VOC difficult).
        area: float64 ``(M,)`` declared areas (NaN: none).
        segmentation: per row its COCO segmentation, or ``None`` (the object is its box).
    """

    start: np.ndarray
    box: np.ndarray
    cls: np.ndarray
    ignore: np.ndarray
    area: np.ndarray
    segmentation: tuple

    @cached_property
    def names(self) -> list[str]:
        """``cls`` as a list."""
        return self.cls.tolist()

    @cached_property
    def segmented(self) -> np.ndarray:
        """bool ``(M,)``: rows with a segmentation (to decode)."""
        return np.array([g is not None for g in self.segmentation], bool).reshape(-1)

    @cached_property
    def any_ignore(self) -> _AnyIgnore:
        """``any_ignore[a:b]``: whether rows ``a:b`` hold a don't-care one."""
        return _AnyIgnore(np.concatenate([[0], np.cumsum(self.ignore, dtype=np.int64)]))

    def rows(self, i: int) -> range:
        return range(int(self.start[i]), int(self.start[i + 1]))

    def annotation(self, k: int) -> CocoAnnotation:
        """Row ``k`` as the annotation that paints it (its segmentation, else its box)."""
        return CocoAnnotation(
            -1, self.cls[k], tuple(self.box[k].tolist()), self.segmentation[k], bool(self.ignore[k])
        )


class _AnyIgnore:
    """Slices of a cumulative count: ``[a:b]`` is whether the count grows in ``a:b``."""

    def __init__(self, cumulative: np.ndarray) -> None:
        self.cumulative = cumulative.tolist()

    def __getitem__(self, rows: slice) -> bool:
        return self.cumulative[rows.stop] > self.cumulative[rows.start]


def _rows_of(start: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """The object rows of images ``idx`` (image by image, in order)."""
    count = start[idx + 1] - start[idx]
    offset = np.repeat(start[idx] - (np.cumsum(count) - count), count)
    return np.arange(int(count.sum())) + offset


def _grouped(image: np.ndarray, n_images: int, **columns) -> ObjectColumns:
    """:class:`ObjectColumns` from per-row image positions (rows of an image kept in order)."""
    order = np.argsort(image, kind="stable")
    start = np.zeros(n_images + 1, np.int64)
    np.cumsum(np.bincount(image, minlength=n_images), out=start[1:])
    seg = columns.pop("segmentation")
    return ObjectColumns(
        start,
        segmentation=tuple(seg[k] for k in order.tolist()),
        **{k: v[order] for k, v in columns.items()},
    )


class AnnotatedDataset(FileDataset):
    """Images with their objects: entries ``(image path, (H, W) or None, name)`` and the
    objects of all of them as :class:`ObjectColumns`; built by :func:`coco_dataset` /
    :func:`voc_dataset`. Every image is annotated once (a second annotation would count it
    twice); an image file need exist only when its pixels are read.
    """

    def _sample(self) -> list[dict]:
        """No items: every annotation is its own target, so there is no instance plane to
        check for split or merged objects (and reading images for it would cost reads)."""
        return []

    def __init__(
        self,
        scheme: str,
        root: Path,
        entries: list,
        objects: ObjectColumns,
        annotation_files: list,
        *,
        image_ids: list[int] | None = None,
        **kw,
    ):
        self.scheme = scheme
        super().__init__(root, **kw)
        self.items = entries
        self.objects = objects
        self.image_ids = image_ids
        self.missing, seen = set(), {}
        for e in entries:  # one image under two names (sub/../a.png, a link) is refused
            key = _identity(e[0])
            if key is None:
                self.missing.add(e[0])
                key = os.path.normpath(e[0])
            if key in seen:
                raise EvalError(
                    f"{scheme} annotations describe image {e[0]} more than once"
                    + ("" if seen[key] == e[0] else f" (also as {seen[key]})")
                )
            seen[key] = e[0]
        self.options["missing_images"] = len(self.missing)
        self.shared_files = list(annotation_files)

    def item_files(self, i: int) -> list[Path]:
        path = self.items[i][0]
        return [] if path in self.missing else [Path(path)]

    def item_key(self, i: int) -> dict:
        key = {"name": self.items[i][2], "path": self.items[i][0]}
        if self.image_ids is not None:
            key["image_id"] = self.image_ids[i]
        return key

    def limit(self, n: int | None) -> None:
        super().limit(n)
        if n is not None and self.image_ids is not None:
            self.image_ids = self.image_ids[:n]

    def load_truth(self, i: int) -> dict:
        """The item without reading its image (zeros of the annotated shape)."""
        return self.load(i, images=False)

    def truth_targets(self, i: int) -> tuple[Targets, tuple[int, int], dict]:
        """Item ``i``'s ground truth as given, its image size and meta, from the annotations
        alone: no image read, no pixel plane (only segmentations are decoded).

        Raises:
            BadItemError: the annotations give no size and the image cannot be read, or a
                segmentation cannot be decoded.
        """
        return self._checked(self._truth_targets, i)

    def truth_batch(self, indices: list[int]) -> list[tuple] | None:
        """The ground truth of items ``indices`` stacked per image size, straight from the
        annotation columns: ``[(shape, items, GroundTruth, metas)]`` (images of one size
        in the order given), the same as :meth:`truth_targets` item by item; ``None`` when
        an item needs more than its columns (a segmentation to decode, a size to read from
        its image), or an index is out of range."""
        n = len(self)
        if any(not 0 <= i < n or self.items[i][1] is None for i in indices):
            return None
        obj, idx = self.objects, np.asarray(indices, np.int64).reshape(-1)
        if obj.segmented[_rows_of(obj.start, idx)].any():
            return None
        out = []
        shapes = [tuple(self.items[i][1]) for i in indices]
        for shape in dict.fromkeys(shapes):
            items = [i for i, s in zip(indices, shapes, strict=True) if s == shape]
            out.append(self._stacked(items, (int(shape[0]), int(shape[1]))))
        return out

    def _stacked(self, items: list[int], shape: tuple[int, int]) -> tuple:
        """:meth:`truth_batch` of items of one size."""
        obj, idx = self.objects, np.asarray(items, np.int64).reshape(-1)
        rows = _rows_of(obj.start, idx)
        plane = np.repeat(np.arange(idx.size), obj.start[idx + 1] - obj.start[idx])
        crowd = obj.ignore[rows]
        real, regions = rows[~crowd], rows[crowd]
        n_real = np.bincount(plane[~crowd], minlength=idx.size)
        metas = []
        for k, i in enumerate(items):
            a, b = int(obj.start[i]), int(obj.start[i + 1])
            classes = [
                c for c, g in zip(obj.names[a:b], obj.ignore[a:b].tolist(), strict=True) if not g
            ]
            meta = self._meta(i, bool(n_real[k]), classes)
            meta["index"] = i
            metas.append(meta)
        spacing = spacings(metas)
        gt = GroundTruth.build(
            plane[~crowd],
            obj.box[real],
            planes=idx.size,
            shape=shape,
            classes=obj.cls[real].tolist(),
            crowd=Regions.build(
                plane[crowd], obj.box[regions], shape=shape, classes=obj.cls[regions].tolist()
            ),
            box_only=n_real > 0,
            spacing=spacing,
            length_m=np.full(real.size, np.nan),
            declared_area=obj.area[real],
        )
        return shape, items, gt, metas

    def _meta(self, i: int, boxes_only: bool, classes: list[str]) -> dict:
        """Item ``i``'s meta: ``gt`` ``"box"`` when a target is a box (box IoU), its
        targets' classes and its COCO id."""
        path, _, name = self.items[i]
        meta = self.base_meta(name, path, None, gt="box" if boxes_only else "mask")
        meta["classes"] = classes
        if self.image_ids is not None:
            meta["image_id"] = self.image_ids[i]
        return meta

    def _size(self, i: int) -> tuple[int, int]:
        path, size, _ = self.items[i]
        if size is None:
            if path in self.missing:
                raise FileFormatError(path, "does not exist and no annotation gives its size")
            size = raster_shape(path)[:2]
        return int(size[0]), int(size[1])

    def _truth_targets(self, i: int) -> tuple[Targets, tuple[int, int], dict]:
        path = self.items[i][0]
        shape = self._size(i)
        rows = self.objects.rows(i)
        segmented = [k for k in rows if self.objects.segmentation[k] is not None]
        pixels: list = [None] * len(rows)
        if segmented:
            try:
                decoded = annotation_pixels(
                    [self.objects.annotation(k) for k in segmented], *shape, checked=True
                )
            except FileFormatError as exc:
                raise FileFormatError(path, exc.problem) from None
            for k, pix in zip(segmented, decoded, strict=True):
                pixels[k - rows.start] = pix
        targets = _targets(self.objects, rows, pixels)
        boxes_only = any(p is None for p in targets.pixels)  # a box target: box IoU
        return targets, shape, self._meta(i, boxes_only, list(targets.classes))

    def load(self, i: int, images: bool = True) -> dict:
        path, size, _ = self.items[i]
        if path in self.missing and (images or size is None):
            raise FileFormatError(
                path,
                "does not exist (scoring saved predictions reads no "
                "image; detectors that read pixels need it)",
            )
        shape = tuple(size) if size is not None and not images else raster_shape(path)[:2]
        if size is not None and tuple(shape) != tuple(size):
            raise FileFormatError(
                path, f"is {shape[1]}x{shape[0]} but its annotation says {size[1]}x{size[0]}"
            )
        if images:
            raw = read_samples(Path(path), self.sample_type, max_pixels=self.max_pixels)
            samples = self.intensity(raw, Path(path))
        else:
            samples = np.zeros(shape, np.float32)
        inst = np.zeros(shape[0] * shape[1], np.int32)
        ignore = np.zeros(inst.size, bool)
        rows = self.objects.rows(i)
        try:
            pixels = annotation_pixels(
                [self.objects.annotation(k) for k in rows], *shape, checked=True
            )  # (read_coco checked every segmentation)
        except FileFormatError as exc:
            raise FileFormatError(path, exc.problem) from None
        targets = _targets(self.objects, rows, pixels)
        k = 0
        for is_ignore, pix in zip(
            self.objects.ignore[rows.start : rows.stop].tolist(), pixels, strict=True
        ):
            if is_ignore:
                ignore[pix] = True
            else:
                k += 1
                inst[pix] = k  # painted in order (pictures and pixel metrics only)
        inst, ignore = inst.reshape(shape), ignore.reshape(shape)
        boxes_only = any(p is None for p in targets.pixels)  # a box target: box IoU
        meta = self._meta(i, boxes_only, list(targets.classes))
        meta["box_source"] = "annotation"  # box IoU uses these boxes, as pycocotools
        if np.isfinite(targets.areas).any():
            meta["areas"] = [None if a != a else float(a) for a in targets.areas.tolist()]
        item = make_item(samples, inst, ignore, meta, boxes=[tuple(b) for b in targets.boxes])
        item["targets"] = targets
        return item


def _targets(objects: ObjectColumns, rows: range, pixels: list) -> Targets:
    """An item's ground truth as given: each annotation its own target (its segmentation's
    pixels, or its box), don't-care ones (crowd, difficult) regions of their class.
    ``pixels``: per row its decoded pixels (used for segmented rows only)."""
    a, b = rows.start, rows.stop
    seg, cls = objects.segmentation[a:b], objects.names[a:b]
    if not objects.any_ignore[a:b]:  # (the common case, without an index per row)
        n = b - a
        return Targets(
            objects.box[a:b],
            tuple(cls),
            tuple(p if s is not None else None for p, s in zip(pixels, seg, strict=True)),
            objects.area[a:b],
            np.full(n, np.nan),
            np.full(n, np.nan),
        )
    ignore = objects.ignore[a:b]
    real, crowd = np.flatnonzero(~ignore).tolist(), np.flatnonzero(ignore).tolist()
    box, n = objects.box[a:b], len(real)
    # checked when the annotation file was read: built as they are
    return Targets(
        box[real],
        tuple(cls[k] for k in real),
        tuple(pixels[k] if seg[k] is not None else None for k in real),
        objects.area[a:b][real],
        np.full(n, np.nan),
        np.full(n, np.nan),
        box[crowd],
        tuple(cls[k] for k in crowd),
        tuple(pixels[k] if seg[k] is not None else None for k in crowd),
    )


def _identity(path: str) -> tuple[int, int] | None:
    """``(device, inode)`` of a regular file, ``None`` when there is none (missing, a
    name the system refuses, a folder, a FIFO)."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return (st.st_dev, st.st_ino) if stat.S_ISREG(st.st_mode) else None


def _exists(path: Path) -> bool:
    try:
        return path.exists()
    except (OSError, ValueError):
        return False


def _inside(folder: Path, name: str, what: str) -> Path:
    """``folder / name``, refused when it resolves outside ``folder`` (see the module
    docstring); ``what`` names the file and field in the message."""
    path = folder / name
    try:
        real, base = path.resolve(), folder.resolve()
    except (OSError, RuntimeError) as exc:  # a link loop
        raise EvalError(f"{what} {name!r} cannot be resolved ({exc})") from None
    if base in real.parents:
        return path
    raise EvalError(
        f"{what} {name!r} resolves to {real}, outside the image folder {folder}; refused "
        "(the dataset option outside=allow reads images outside it)"
    )


def _all_inside(folder: Path, names: list[str], what: Callable[[int], str]) -> None:
    """:func:`_inside` for many names at once (``what(k)`` names name ``k``'s file and
    field): names that stay inside lexically and whose folders resolve inside (each
    distinct folder resolved once) need no resolution of their own unless the file is a
    symbolic link."""
    base, top = folder.resolve(), os.fspath(folder)
    parents: dict[str, bool] = {}
    for k, name in enumerate(names):
        norm = os.path.normpath(name)
        if os.path.isabs(norm) or norm == ".." or norm.startswith(".." + os.sep):
            _inside(folder, name, what(k))  # refused, with the resolved path in the message
            continue
        parent = os.path.dirname(norm)
        if parent not in parents:
            real = (folder / parent).resolve() if parent else base
            parents[parent] = real == base or base in real.parents
        if not parents[parent] or os.path.islink(os.path.join(top, norm)):
            _inside(folder, name, what(k))


def _joined(folder: str, name: str) -> str:
    """``str(Path(folder) / name)`` (without building a path for a plain name)."""
    return (
        os.path.join(folder, name) if os.path.normpath(name) == name else str(Path(folder) / name)
    )


def coco_dataset(
    path: Path, images: Path | None, limit: int | None, *, outside: bool = False, **kw
) -> AnnotatedDataset:
    """``coco:FILE.json``: images under ``images`` (default: the JSON's folder); with
    ``outside``, also images whose ``file_name`` resolves outside that folder."""
    try:
        coco = read_coco_table(path, max_pixels=kw.get("max_pixels", DEFAULT_MAX_PIXELS))
    except FileFormatError as exc:
        raise EvalError(str(exc)) from exc
    folder = images or path.parent
    names = [im["file_name"] for im in coco.images]
    if not outside:
        _all_inside(
            folder, names, lambda k: f"{path}: images[{k}] (id {coco.images[k]['id']}) file_name"
        )
    ids = np.array([im["id"] for im in coco.images], np.int64)
    order = np.argsort(ids, kind="stable")  # pycocotools' image order
    position = np.empty_like(order)
    position[order] = np.arange(order.size)
    cats = np.array(list(coco.categories.values()), dtype=object)
    codes = {c: k for k, c in enumerate(coco.categories)}
    category = np.array([codes[c] for c in coco.category.tolist()], np.int64)
    objects = _grouped(
        position[coco.image],
        order.size,
        box=coco.box,
        cls=cats[category].reshape(-1),
        ignore=coco.iscrowd,
        area=coco.area,
        segmentation=coco.segmentation,
    )
    base = os.fspath(folder)
    entries = [
        (_joined(base, names[k]), (coco.images[k]["height"], coco.images[k]["width"]), names[k])
        for k in order.tolist()
    ]
    ds = AnnotatedDataset(
        "coco", path, entries, objects, [path], image_ids=ids[order].tolist(), **kw
    )
    ds.options.update(
        images=str(folder),
        categories=sorted(set(coco.categories.values())),
        outside=OUTSIDE[outside],
    )
    ds.categories = dict(coco.categories)  # id -> name: saved predictions give ids
    if coco.categories:
        ds.default_class = coco.categories[min(coco.categories)]
    ds.options["labels"] = "COCO segmentation (box when absent); iscrowd = ignore"
    ds.finish("annotation", limit)
    return ds


def _voc_image(xml: Path, filename: str, images: Path | None, outside: bool) -> Path:
    """The image of a VOC file: ``images/filename``, else VOC's ``../JPEGImages``, else
    beside; inside the folder it is found in unless ``outside``."""
    folders = [f for f in (images, xml.parent.parent / "JPEGImages", xml.parent) if f]
    folder = next((f for f in folders if _exists(f / filename)), folders[0])
    if outside:
        return folder / filename
    return _inside(folder, filename, f"{xml}: <filename>")


def voc_dataset(
    root: Path, images: Path | None, limit: int | None, *, outside: bool = False, **kw
) -> AnnotatedDataset:
    """``voc:DIR``: every ``*.xml`` under ``DIR`` (e.g. ``DIR/Annotations``); with
    ``outside``, also images whose ``<filename>`` resolves outside their folder."""
    require_dir(root, "voc")
    xmls = [f for f in walk_files(root) if f.suffix.lower() == ".xml"]
    if not xmls:
        raise EvalError(f"no VOC *.xml annotation files found in {root}")
    entries, objs = [], []
    for xml in xmls:
        try:
            ann = read_voc(xml, max_pixels=kw.get("max_pixels", DEFAULT_MAX_PIXELS))
        except FileFormatError as exc:
            raise EvalError(str(exc)) from exc
        objs.extend((len(entries), o) for o in ann.objects)
        img = _voc_image(xml, ann.filename, images, outside)
        entries.append((str(img), (ann.height, ann.width), str(xml.relative_to(root))))
    m = len(objs)
    objects = _grouped(
        np.array([k for k, _ in objs], np.int64).reshape(m),
        len(entries),
        box=np.array([o.box for _, o in objs], np.float64).reshape(m, 4),
        cls=np.array([o.name for _, o in objs], dtype=object).reshape(m),
        ignore=np.array([o.difficult for _, o in objs], bool).reshape(m),
        area=np.full(m, np.nan),
        segmentation=(None,) * m,
    )
    ds = AnnotatedDataset("voc", root, entries, objects, xmls, **kw)
    ds.options["labels"] = "VOC boxes (gt=box); difficult = ignore"
    ds.options["outside"] = OUTSIDE[outside]
    ds.finish("annotation", limit)
    return ds


def _kw(spec: DatasetSpec) -> dict:
    spec.check_keys(ANNOTATED_OPTIONS)
    return {
        "sample_type": spec.sample_type("display"),
        "spacing": spec.spacing(),
        "max_pixels": spec.max_pixels(),
        "outside": spec.choice("outside", OUTSIDE, "refuse") == "allow",
    }


def coco_from_spec(spec: DatasetSpec, limit: int | None) -> AnnotatedDataset:
    """``coco:FILE.json[?images=DIR&outside=allow]``."""
    images = spec.options.get("images")
    return coco_dataset(Path(spec.path), images and Path(images), limit, **_kw(spec))


def voc_from_spec(spec: DatasetSpec, limit: int | None) -> AnnotatedDataset:
    """``voc:DIR[?images=DIR&outside=allow]``."""
    images = spec.options.get("images")
    return voc_dataset(Path(spec.path), images and Path(images), limit, **_kw(spec))
