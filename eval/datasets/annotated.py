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
from collections import Counter
from pathlib import Path

import numpy as np

from torchsar.io import (
    FileFormatError,
    raster_shape,
    read_coco,
    read_voc,
)
from torchsar.io.coco import CocoAnnotation, annotation_pixels
from torchsar_eval.datasets.base import FileDataset, make_item, require_dir, walk_files
from torchsar_eval.datasets.images import read_samples
from torchsar_eval.datasets.spec import DEFAULT_MAX_PIXELS, DatasetSpec
from torchsar_eval.errors import EvalError
from torchsar_eval.items import Targets

__all__ = ["ANNOTATED_OPTIONS", "AnnotatedDataset", "coco_from_spec", "voc_from_spec"]

ANNOTATED_OPTIONS = ("images", "type", "spacing", "max_pixels", "outside")
OUTSIDE = ("refuse", "allow")


class AnnotatedDataset(FileDataset):
    """Images with their objects: entries ``(image path, (H, W), objects, name)``, objects
    ``(class, box, painter, ignore)``; built by :func:`coco_dataset` / :func:`voc_dataset`.
    Every image is annotated once (a second annotation would count it twice); an image file
    need exist only when its pixels are read.
    """

    def _sample(self) -> list[dict]:
        """No items: every annotation is its own target, so there is no instance plane to
        check for split or merged objects (and reading images for it would cost reads)."""
        return []

    def __init__(self, scheme: str, root: Path, entries: list, annotation_files: list, *,
                 image_ids: list[int] | None = None, **kw):  # fmt: skip
        self.scheme = scheme
        super().__init__(root, **kw)
        self.items = entries
        self.image_ids = image_ids
        self.missing = {str(e[0]) for e in entries if not _is_file(e[0])}
        self.options["missing_images"] = len(self.missing)
        twice = [path for path, k in Counter(e[0] for e in entries).items() if k > 1]
        if twice:
            raise EvalError(f"{scheme} annotations describe image {twice[0]} more than once")
        self.shared_files = list(annotation_files)

    def item_files(self, i: int) -> list[Path]:
        path = self.items[i][0]
        return [] if str(path) in self.missing else [path]

    def item_key(self, i: int) -> dict:
        key = {"name": self.items[i][3], "path": str(self.items[i][0])}
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

    def _truth_targets(self, i: int) -> tuple[Targets, tuple[int, int], dict]:
        path, size, objects, name = self.items[i]
        if size is None:
            if str(path) in self.missing:
                raise FileFormatError(path, "does not exist and no annotation gives its size")
            size = raster_shape(path)[:2]
        shape = (int(size[0]), int(size[1]))
        segmented = [k for k, (_, _, o, _) in enumerate(objects) if o.segmented]
        try:
            decoded = annotation_pixels([objects[k][2].ann for k in segmented], *shape,
                                        checked=True) if segmented else []  # fmt: skip
        except FileFormatError as exc:
            raise FileFormatError(path, exc.problem) from None
        pixels: list = [None] * len(objects)
        for k, pix in zip(segmented, decoded, strict=True):
            pixels[k] = pix
        targets = _targets(objects, pixels, shape)
        boxes_only = any(p is None for p in targets.pixels)  # a box target: box IoU
        meta = self.base_meta(name, path, None, gt="box" if boxes_only else "mask")
        meta["classes"] = list(targets.classes)
        if self.image_ids is not None:
            meta["image_id"] = self.image_ids[i]
        return targets, shape, meta

    def load(self, i: int, images: bool = True) -> dict:
        path, size, objects, name = self.items[i]
        if str(path) in self.missing and (images or size is None):
            raise FileFormatError(path, "does not exist (scoring saved predictions reads no "
                                  "image; detectors that read pixels need it)")  # fmt: skip
        shape = tuple(size) if size is not None and not images else raster_shape(path)[:2]
        if size is not None and tuple(shape) != tuple(size):
            raise FileFormatError(
                path, f"is {shape[1]}x{shape[0]} but its annotation says {size[1]}x{size[0]}"
            )
        if images:
            samples = self.intensity(read_samples(path, self.sample_type,
                                                  max_pixels=self.max_pixels), path)  # fmt: skip
        else:
            samples = np.zeros(shape, np.float32)
        inst = np.zeros(shape[0] * shape[1], np.int32)
        ignore = np.zeros(inst.size, bool)
        try:
            pixels = annotation_pixels([_painted(o, box) for _, box, o, _ in objects], *shape,
                                       checked=True)  # (read_coco checked every segmentation)
        except FileFormatError as exc:
            raise FileFormatError(path, exc.problem) from None
        targets = _targets(objects, pixels, shape)
        k = 0
        for (_, _, _, is_ignore), pix in zip(objects, pixels, strict=True):
            if is_ignore:
                ignore[pix] = True
            else:
                k += 1
                inst[pix] = k  # painted in order (pictures and pixel metrics only)
        inst, ignore = inst.reshape(shape), ignore.reshape(shape)
        boxes_only = any(p is None for p in targets.pixels)  # a box target: box IoU
        meta = self.base_meta(name, path, None, gt="box" if boxes_only else "mask")
        meta["classes"] = list(targets.classes)
        meta["box_source"] = "annotation"  # box IoU uses these boxes, as pycocotools
        if np.isfinite(targets.areas).any():
            meta["areas"] = [None if a != a else float(a) for a in targets.areas.tolist()]
        if self.image_ids is not None:
            meta["image_id"] = self.image_ids[i]
        item = make_item(samples, inst, ignore, meta, boxes=[tuple(b) for b in targets.boxes])
        item["targets"] = targets
        return item


def _targets(objects: list, pixels: list, shape: tuple[int, int]) -> Targets:
    """The item's ground truth as given: each annotation its own target (its segmentation's
    pixels, or its box), don't-care ones (crowd, difficult) regions of their class."""
    real = [(o, p) for o, p in zip(objects, pixels, strict=True) if not o[3]]
    crowd = [(o, p) for o, p in zip(objects, pixels, strict=True) if o[3]]
    n = len(real)
    # checked when the annotation file was read: built as they are
    return Targets(
        np.array([o[1] for o, _ in real], np.float64).reshape(n, 4),
        tuple(o[0] for o, _ in real),
        tuple(p if o[2].segmented else None for o, p in real),  # (boxes: None)
        np.array([np.nan if o[2].area is None else o[2].area for o, _ in real], np.float64),
        np.full(n, np.nan), np.full(n, np.nan),
        np.array([o[1] for o, _ in crowd], np.float64).reshape(len(crowd), 4),
        tuple(o[0] for o, _ in crowd),
        tuple(p if o[2].segmented else None for o, p in crowd),
    )  # fmt: skip


def _is_file(path: Path) -> bool:
    """``path.is_file()``, false for a name the system refuses (too long, say)."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


def _exists(path: Path) -> bool:
    try:
        return path.exists()
    except (OSError, ValueError):
        return False


def _painted(painter: _Painter, box) -> CocoAnnotation:
    """The annotation a painter paints (a bare box for VOC objects)."""
    if painter.ann is not None:
        return painter.ann
    return CocoAnnotation(-1, "", tuple(box), None, False)


class _Painter:
    """What paints one object: its COCO annotation (decoded with the image's others), or
    a filled box."""

    __slots__ = ("ann", "area", "box", "segmented")

    def __init__(self, box, coco_annotation=None) -> None:
        self.box, self.ann = box, coco_annotation
        self.segmented = coco_annotation is not None and coco_annotation.segmentation is not None
        self.area = None if coco_annotation is None else coco_annotation.area


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


def _all_inside(folder: Path, names: list[str], what: list[str]) -> None:
    """:func:`_inside` for many names at once: names that stay inside lexically and whose
    folders resolve inside (each distinct folder resolved once) need no resolution of
    their own unless the file is a symbolic link."""
    base = folder.resolve()
    parents: dict[str, bool] = {}
    for name, w in zip(names, what, strict=True):
        norm = os.path.normpath(name)
        if os.path.isabs(norm) or norm == ".." or norm.startswith(".." + os.sep):
            _inside(folder, name, w)  # refused, with the resolved path in the message
            continue
        parent = os.path.dirname(norm)
        if parent not in parents:
            real = (folder / parent).resolve() if parent else base
            parents[parent] = real == base or base in real.parents
        if not parents[parent] or os.path.islink(folder / norm):
            _inside(folder, name, w)


def coco_dataset(
    path: Path, images: Path | None, limit: int | None, *, outside: bool = False, **kw
) -> AnnotatedDataset:
    """``coco:FILE.json``: images under ``images`` (default: the JSON's folder); with
    ``outside``, also images whose ``file_name`` resolves outside that folder."""
    try:
        coco = read_coco(path, max_pixels=kw.get("max_pixels", DEFAULT_MAX_PIXELS))
    except FileFormatError as exc:
        raise EvalError(str(exc)) from exc
    folder = images or path.parent
    if not outside:
        _all_inside(folder, [im.file_name for im in coco.images],
                    [f"{path}: images[{k}] (id {im.id}) file_name"
                     for k, im in enumerate(coco.images)])  # fmt: skip
    ordered = sorted(coco.images, key=lambda im: im.id)  # pycocotools' image order
    entries = [
        (
            folder / im.file_name,
            (im.height, im.width),
            [(a.category, a.box, _Painter(a.box, a), a.iscrowd) for a in im.annotations],
            im.file_name,
        )
        for im in ordered
    ]
    ids = [im.id for im in ordered]
    ds = AnnotatedDataset("coco", path, entries, [path], image_ids=ids, **kw)
    ds.options.update(images=str(folder), categories=sorted(set(coco.categories.values())),
                      outside=OUTSIDE[outside])  # fmt: skip
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
    entries = []
    for xml in xmls:
        try:
            ann = read_voc(xml, max_pixels=kw.get("max_pixels", DEFAULT_MAX_PIXELS))
        except FileFormatError as exc:
            raise EvalError(str(exc)) from exc
        objs = [(o.name, o.box, _Painter(o.box), o.difficult) for o in ann.objects]
        img = _voc_image(xml, ann.filename, images, outside)
        entries.append((img, (ann.height, ann.width), objs, str(xml.relative_to(root))))
    ds = AnnotatedDataset("voc", root, entries, xmls, **kw)
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
