"""COCO instance annotations: images, categories, boxes, polygons and RLE masks.

Masks are decoded with ``pycocotools`` (polygons, uncompressed and compressed RLE). Boxes
are COCO ``[x, y, width, height]`` and are returned as ``(r0, c0, r1, c1)`` end-exclusive.
Crowd annotations (``iscrowd=1``) are kept apart so callers can make them don't-care.

:func:`read_coco` checks every field against its image before any mask is decoded (the
decoder allocates in proportion to the coordinates it is given, so one polygon vertex at
``1e300`` would exhaust memory):

- ``images``: objects with an integer ``id`` (each listed once; the very same record
  listed again is read once, with an :class:`~torchsar.io.errors.AnnotationWarning`), a
  ``file_name`` (each named once), and positive integer ``height`` and ``width`` whose
  product is at most ``max_pixels``.
- ``categories``: objects with an integer ``id`` and a ``name``.
- ``annotations``: objects with a known ``image_id`` and ``category_id``; a ``bbox`` of
  four finite numbers with non-negative width and height, inside the image; ``iscrowd``
  0 or 1; ``area``, when given, a finite non-negative number; a repeated annotation ``id``
  is kept, with an :class:`~torchsar.io.errors.AnnotationWarning`.
- ``segmentation`` (optional): polygons, each an even number (at least 6) of finite
  coordinates ``[x0, y0, x1, y1, ...]`` within :data:`POLYGON_TOLERANCE` (one pixel) of
  the image, ``0 <= x <= width``, ``0 <= y <= height``; or an RLE whose ``size`` is the
  image's ``[height, width]`` and whose ``counts`` (a list, or a string in COCO's compressed
  form) are non-negative run lengths summing to ``height * width``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from torchsar.io import jsontext
from torchsar.io.errors import AnnotationWarning, FileFormatError
from torchsar.io.raster import DEFAULT_MAX_PIXELS, check_regular_file
from torchsar.io.rle import check_strings

__all__ = [
    "POLYGON_TOLERANCE",
    "CocoAnnotation",
    "CocoImage",
    "CocoSet",
    "CocoTable",
    "annotation_mask",
    "annotation_pixels",
    "read_coco",
    "read_coco_table",
    "segmentation_counts",
    "segmentation_problem",
    "segmentation_problems",
]

POLYGON_TOLERANCE = 1.0
"""How far (pixels) a polygon vertex may lie outside the image: annotation tools round
vertices on the border outwards; the decoder clips them to the image."""


@dataclass(frozen=True)
class CocoAnnotation:
    """One object: ``box`` ``(r0, c0, r1, c1)``, ``segmentation`` as stored (or ``None``)."""

    id: int
    category: str
    box: tuple[float, float, float, float]
    segmentation: object
    iscrowd: bool
    area: float | None = None


@dataclass(frozen=True)
class CocoImage:
    """One image of the set with its annotations (in file order)."""

    id: int
    file_name: str
    height: int
    width: int
    annotations: tuple[CocoAnnotation, ...]


@dataclass(frozen=True)
class CocoSet:
    """A parsed annotation file: images in file order, category names by id."""

    images: tuple[CocoImage, ...]
    categories: dict[int, str]


@dataclass(frozen=True, eq=False)
class CocoTable:
    """A parsed annotation file as columns (:func:`read_coco_table`): the image records in
    file order, and one row per annotation, in file order.

    Attributes:
        images: ``{"id", "file_name", "height", "width"}`` per image.
        categories: category names by id.
        image: int64 ``(M,)``, each annotation's row in ``images``.
        id: int64 ``(M,)`` annotation ids (-1: none given).
        category: int64 ``(M,)`` category ids.
        box: float64 ``(M, 4)`` ``(r0, c0, r1, c1)``, end-exclusive.
        iscrowd: bool ``(M,)``.
        area: float64 ``(M,)`` the declared ``area`` (NaN: none).
        segmentation: per annotation its segmentation as stored, or ``None``.
    """

    images: tuple[dict, ...]
    categories: dict[int, str]
    image: np.ndarray
    id: np.ndarray
    category: np.ndarray
    box: np.ndarray
    iscrowd: np.ndarray
    area: np.ndarray
    segmentation: tuple

    def to_set(self) -> CocoSet:
        """The same annotations as objects (:class:`CocoSet`)."""
        anns: list[list[CocoAnnotation]] = [[] for _ in self.images]
        for k, (row, box) in enumerate(zip(self.image.tolist(), self.box.tolist(), strict=True)):
            area = float(self.area[k])
            name = self.categories[int(self.category[k])]
            anns[row].append(
                CocoAnnotation(
                    int(self.id[k]),
                    name,
                    tuple(box),
                    self.segmentation[k],
                    bool(self.iscrowd[k]),
                    None if area != area else area,
                )
            )
        return CocoSet(
            tuple(
                CocoImage(**rec, annotations=tuple(a))
                for rec, a in zip(self.images, anns, strict=True)
            ),
            self.categories,
        )


def _is_int(v: object) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _finite(v: object) -> float | None:
    """``v`` as a float if it is a finite JSON number (not a bool), else ``None``."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return None
    try:
        f = float(v)
    except OverflowError:  # an integer of hundreds of digits
        return None
    return f if math.isfinite(f) else None


def _all_finite(values: list) -> bool:
    """Whether every value is a finite JSON number (not a bool)."""
    if not set(map(type, values)) <= {int, float}:
        return False
    try:
        return all(map(math.isfinite, values))
    except OverflowError:  # an integer of hundreds of digits
        return False


def _show(v: object) -> str:
    """A short repr of a value for a message."""
    text = repr(v)
    return text if len(text) <= 40 else text[:37] + "..."


def _load_json(path: str | Path) -> dict:
    """The top-level object of a COCO file, or an error naming it."""
    check_regular_file(path)
    try:
        data = jsontext.read_json(path)  # (its reader pauses the collector)
    except RecursionError:
        raise FileFormatError(path, "is not a readable JSON file (nested too deeply)") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:  # ValueError: too many digits
        raise FileFormatError(path, f"is not a readable JSON file ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("images"), list):
        raise FileFormatError(path, "is not a COCO annotation file (no 'images' list)")
    for key in ("annotations", "categories"):
        if key in data and not isinstance(data[key], list):
            what = "{id, image_id, category_id, bbox}" if key == "annotations" else "{id, name}"
            raise FileFormatError(
                path, f"'{key}' must be a list of {what}, got {type(data[key]).__name__}"
            )
    return data


def _categories(entries: list, path) -> dict[int, str]:
    """Category names by id; every entry an object with an integer id and a name."""
    out: dict[int, str] = {}
    for k, c in enumerate(entries):
        if not isinstance(c, dict):
            raise FileFormatError(path, f"categories[{k}] is not an object: {_show(c)}")
        if not _is_int(c.get("id")):
            raise FileFormatError(path, f"categories[{k}] has no integer id: {_show(c)}")
        if not isinstance(c.get("name"), str) or not c["name"]:
            raise FileFormatError(path, f"categories[{k}] has no name (a string): {_show(c)}")
        if out.get(c["id"], c["name"]) != c["name"]:
            raise FileFormatError(
                path,
                f"categories[{k}] gives id {c['id']} a second name "
                f"({out[c['id']]!r}, {c['name']!r})",
            )
        out[c["id"]] = c["name"]
    return out


def _dimension(im: dict, key: str, where: str, path) -> int:
    v = im.get(key)
    if isinstance(v, float) and v.is_integer():
        v = int(v)
    if not _is_int(v) or v <= 0:
        raise FileFormatError(path, f"{where} {key} {_show(v)} must be a positive integer")
    return v


def _images(entries: list, path, max_pixels: int) -> list[dict]:
    """Validated image records in file order; ids and file names unique."""
    records: list[dict] = []
    by_id: dict[int, tuple[int, dict]] = {}  # id -> (entry, record)
    by_name: dict[str, tuple[int, int]] = {}  # file name -> (entry, id)
    for k, im in enumerate(entries):
        if not isinstance(im, dict):
            raise FileFormatError(path, f"images[{k}] is not an object: {_show(im)}")
        if not _is_int(im.get("id")):
            raise FileFormatError(path, f"images[{k}] has no integer id: {_show(im)}")
        where = f"images[{k}] (id {_show(im['id'])})"
        name = im.get("file_name")
        if not isinstance(name, str) or not name:
            raise FileFormatError(path, f"{where} has no file_name (a string)")
        h, w = (_dimension(im, key, where, path) for key in ("height", "width"))
        if h * w > max_pixels:
            raise FileFormatError(
                path,
                f"{where} {name} is {w}x{h} = {w * h:,} pixels, over the limit of "
                f"{max_pixels:,} (raise it with max_pixels)",
            )
        rec = {"id": im["id"], "file_name": name, "height": h, "width": w}
        if im["id"] in by_id:
            j, first = by_id[im["id"]]
            if first == rec:  # the same record again: harmless, but say so
                warnings.warn(
                    f"{path}: images[{j}] is listed again as images[{k}]; read once",
                    AnnotationWarning,
                    stacklevel=3,
                )
                continue
            raise FileFormatError(
                path,
                f"images[{j}] and images[{k}] both have id {im['id']} "
                f"({first['file_name']}, {name})",
            )
        if name in by_name:
            j, other = by_name[name]
            raise FileFormatError(
                path,
                f"images[{j}] (id {other}) and {where} both name file "
                f"{name}; an image is listed once",
            )
        by_id[im["id"]], by_name[name] = (k, rec), (k, im["id"])
        records.append(rec)
    return records


def _polygon_problem(
    k: int, poly: list, height: int, width: int, image: str, tolerance: float
) -> str | None:
    if not set(map(type, poly)) <= {int, float}:  # bool is neither
        return (
            f"segmentation polygon {k} {_show(poly)} is not a list of numbers [x0, y0, x1, y1, ...]"
        )
    if len(poly) < 6 or len(poly) % 2:
        return (
            f"segmentation polygon {k} has {len(poly)} numbers; a polygon is "
            "[x0, y0, x1, y1, x2, y2, ...]: an even count, at least 6"
        )
    if not _all_finite(poly):
        bad = next(v for v in poly if _finite(v) is None)
        return f"segmentation polygon {k} holds {_show(bad)}; coordinates are finite numbers"
    xs, ys = poly[0::2], poly[1::2]
    lo, hi = -tolerance, (width + tolerance, height + tolerance)
    if min(xs) < lo or min(ys) < lo or max(xs) > hi[0] or max(ys) > hi[1]:
        i = next(
            i
            for i, (x, y) in enumerate(zip(xs, ys, strict=True))
            if not (lo <= x <= hi[0] and lo <= y <= hi[1])
        )
        return (
            f"segmentation polygon {k} point {i} ({xs[i]:g}, {ys[i]:g}) lies outside "
            f"{image} ({width}x{height}) by more than {tolerance:g} pixel(s)"
        )
    return None


def _rle_problem(seg: dict, height: int, width: int, image: str) -> tuple[str | None, str | None]:
    """``(problem, string)``: what is wrong with an RLE, or a compressed string still to
    check (with :func:`_string_problems`, many at once)."""
    size, counts = seg.get("size"), seg.get("counts")
    if not (isinstance(size, list) and len(size) == 2 and all(map(_is_int, size))):
        return f"segmentation RLE has no size [height, width]: size {_show(size)}", None
    if size != [height, width]:
        return f"segmentation size {size} is not {image}'s [{height}, {width}]", None
    if isinstance(counts, str):
        return None, counts
    if not isinstance(counts, list) or not all(map(_is_int, counts)):
        return (
            f"segmentation counts {_show(counts)} are neither run lengths (a list of "
            "integers) nor a compressed RLE string"
        ), None
    return _runs_problem(sum(counts), min(counts, default=0), height, width), None


def _runs_problem(total: int, least: int, height: int, width: int) -> str | None:
    """Run lengths must be non-negative and cover the image."""
    if least < 0:
        return f"segmentation counts hold {least}; run lengths are non-negative integers"
    if total != height * width:
        return f"segmentation counts sum to {total}, not {height}x{width} = {height * width}"
    return None


def _string_problems(strings: list[str], sizes: list[tuple[int, int]]) -> list[str | None]:
    """:func:`_runs_problem` of compressed RLE strings, all decoded together."""
    problems, sums, minima = check_strings(strings, [h * w for h, w in sizes])
    return [
        f"segmentation counts {_show(s)} are not COCO compressed RLE: {p}"
        if p is not None
        else _runs_problem(int(total), int(least), h, w)
        for s, p, total, least, (h, w) in zip(strings, problems, sums, minima, sizes, strict=True)
    ]


def _problem_now(
    seg: object, height: int, width: int, image: str, tolerance: float
) -> tuple[str | None, str | None]:
    """``(problem, string)``: what is wrong with ``seg``, or its compressed RLE string
    still to check."""
    if isinstance(seg, dict):
        return _rle_problem(seg, height, width, image)
    if isinstance(seg, list) and seg:
        if not all(isinstance(poly, list) for poly in seg):
            return (
                f"segmentation {_show(seg)} is not a list of polygons [[x0, y0, x1, y1, ...], ...]"
            ), None
        for k, poly in enumerate(seg):
            problem = _polygon_problem(k, poly, height, width, image, tolerance)
            if problem is not None:
                return problem, None
        return None, None
    return (
        f"segmentation {_show(seg)} is neither polygons [[x0, y0, x1, y1, ...], ...] "
        "nor RLE {size, counts}"
    ), None


def segmentation_problems(
    segs: list,
    height: int,
    width: int,
    *,
    image: str | None = None,
    tolerance: float = POLYGON_TOLERANCE,
) -> list[str | None]:
    """What makes each of ``segs`` an invalid COCO segmentation of a ``height x width``
    image (the rules of the module docstring), ``None`` for a valid one; compressed RLE
    strings are checked together, in a few vectorised passes.

    Args:
        segs: segmentations, each polygons ``[[x0, y0, ...], ...]`` or an RLE
            ``{"size", "counts"}``.
        height, width: the image size.
        image: how to name the image in the messages (default ``"the image"``).
        tolerance: how far (pixels) polygon vertices may lie outside the image.

    Examples:
        >>> p = segmentation_problems([[[0, 0, 4, 0, 4, 1e300]], [[0, 0, 4, 0, 4]]], 8, 8)
        >>> p[0].split(" by ")[0]
        'segmentation polygon 0 point 2 (4, 1e+300) lies outside the image (8x8)'
        >>> p[1].split(";")[0]
        'segmentation polygon 0 has 5 numbers'
        >>> segmentation_problems([{"size": [2, 2], "counts": [1, 3]}, {"size": [2, 2],
        ...                        "counts": "52"}], 2, 2)
        [None, 'segmentation counts sum to 7, not 2x2 = 4']
    """
    image = image or "the image"
    out: list[str | None] = []
    pending: list[tuple[int, str]] = []
    for k, seg in enumerate(segs):
        problem, string = _problem_now(seg, height, width, image, tolerance)
        out.append(problem)
        if string is not None:
            pending.append((k, string))
    late = _string_problems([s for _, s in pending], [(height, width)] * len(pending))
    for (k, _), problem in zip(pending, late, strict=True):
        out[k] = problem
    return out


def segmentation_problem(
    seg: object,
    height: int,
    width: int,
    *,
    image: str | None = None,
    tolerance: float = POLYGON_TOLERANCE,
) -> str | None:
    """:func:`segmentation_problems` of one segmentation.

    Examples:
        >>> segmentation_problem({"size": [2, 2], "counts": [1, 3]}, 2, 2) is None
        True
    """
    return segmentation_problems([seg], height, width, image=image, tolerance=tolerance)[0]


def _bbox(a: dict, rec: dict) -> tuple[float, float, float, float] | str:
    """``(x, y, w, h)`` of an annotation, or what is wrong with it."""
    box = a.get("bbox")
    if not (isinstance(box, list) and len(box) == 4 and _all_finite(box)):
        return f"bbox {_show(box)} is not [x, y, width, height] of 4 finite numbers"
    x, y, w, h = map(float, box)
    W, H = rec["width"], rec["height"]
    if w < 0 or h < 0 or x < 0 or y < 0 or x + w > W + 1e-6 or y + h > H + 1e-6:
        return (
            f"box [x={x:g}, y={y:g}, w={w:g}, h={h:g}] lies outside image "
            f"{rec['file_name']} ({W}x{H})"
        )
    return x, y, w, h


def _annotation(k: int, a: object, categories: dict[int, str], images: dict, path) -> tuple:
    """``(image id, CocoAnnotation, where, string)`` of ``annotations[k]``, every field
    checked but a compressed RLE ``string``, left for :func:`_check_strings`."""
    if not isinstance(a, dict):
        raise FileFormatError(path, f"annotations[{k}] is not an object: {_show(a)}")
    aid = a.get("id")
    where = f"annotations[{k}]" + ("" if aid is None else f" (id {_show(aid)})")

    def fail(problem: str) -> FileFormatError:
        return FileFormatError(path, f"{where} {problem}")

    if aid is not None and not _is_int(aid):
        raise fail("id must be an integer")
    image_id, category_id = a.get("image_id"), a.get("category_id")
    if not _is_int(image_id) or image_id not in images:
        raise fail(f"refers to unknown image_id {_show(image_id)}")
    if not _is_int(category_id) or category_id not in categories:
        raise fail(f"has unknown category_id {_show(category_id)}")
    rec = images[image_id]
    box = _bbox(a, rec)
    if isinstance(box, str):
        raise fail(box)
    x, y, w, h = box
    iscrowd = a.get("iscrowd", 0)
    if isinstance(iscrowd, str) or iscrowd not in (0, 1):
        raise fail(f"iscrowd {_show(iscrowd)} must be 0 or 1")
    area = a.get("area")
    if area is not None and (_finite(area) is None or area < 0):
        raise fail(f"area {_show(area)} must be a finite non-negative number")
    seg, string = a.get("segmentation"), None
    if seg is not None and seg != [] and seg != {}:
        image = f"image {rec['file_name']}"
        problem, string = _problem_now(seg, rec["height"], rec["width"], image, POLYGON_TOLERANCE)
        if problem is not None:
            raise fail(problem)
    else:
        seg = None
    ann = CocoAnnotation(
        -1 if aid is None else aid,
        categories[category_id],
        (y, x, y + h, x + w),
        seg,
        bool(iscrowd),
        None if area is None else float(area),
    )
    return image_id, ann, where, string


def _box_columns(entries: list, categories: dict, records: list[dict]) -> dict | None:
    """The annotation columns (see :class:`CocoTable`) when every entry is a plain valid box
    annotation (the checks of :func:`_annotation`, made column by column: no segmentation,
    distinct ids), else ``None``: the entry-by-entry path then names the first problem."""
    if type(entries) is not list or not set(map(type, entries)) <= {dict}:
        return None
    rows = {rec["id"]: k for k, rec in enumerate(records)}
    fields = [
        (
            a.get("image_id"),
            a.get("category_id"),
            a.get("id"),
            a.get("iscrowd", 0),
            a.get("bbox"),
            a.get("area"),
            a.get("segmentation"),
        )
        for a in entries
    ]
    image_ids, category, ids, crowd, boxes, areas, segs = (
        (list(c) for c in zip(*fields, strict=True)) if fields else ([],) * 7
    )
    given = [v for v in ids if v is not None]
    if (
        not set(map(type, image_ids)) <= {int}
        or not set(map(type, category)) <= {int}
        or not set(category) <= categories.keys()
        or not set(map(type, given)) <= {int}
        or len(set(given)) != len(given)
        or not set(map(type, crowd)) <= {int}
        or not set(crowd) <= {0, 1}
        or any(s is not None and s != [] and s != {} for s in segs)
        or not jsontext.plain_boxes(boxes)
        or not set(map(type, areas)) <= {int, float, type(None)}
    ):
        return None
    image = [rows.get(v) for v in image_ids]
    if None in image:
        return None
    n = len(entries)
    try:
        xywh = np.array(boxes, np.float64).reshape(n, 4)
        area = np.array([np.nan if v is None else v for v in areas], np.float64).reshape(n)
    except OverflowError:  # an integer past float range
        return None
    row = np.array(image, np.int64).reshape(n)
    height = np.array([r["height"] for r in records], np.float64)[row]
    width = np.array([r["width"] for r in records], np.float64)[row]
    x, y, w, h = xywh.T
    with np.errstate(over="ignore", invalid="ignore"):
        good = (
            np.isfinite(xywh).all(axis=1)
            & (xywh.min(axis=1, initial=0.0) >= 0)
            & (x + w <= width + 1e-6)
            & (y + h <= height + 1e-6)
            & (np.isnan(area) | ((area >= 0) & (area < np.inf)))
        )
    if not good.all():
        return None
    return {
        "image": row,
        "id": np.array([-1 if v is None else v for v in ids], np.int64).reshape(n),
        "category": np.array(category, np.int64).reshape(n),
        "box": np.stack([y, x, y + h, x + w], axis=1).reshape(n, 4),
        "iscrowd": np.array(crowd, bool).reshape(n),
        "area": area,
        "segmentation": (None,) * n,
    }


def _check_strings(pending: list[tuple[str, str, tuple[int, int]]], path) -> None:
    """Raise for the first bad one of ``(where, compressed string, (h, w))``, checked
    together."""
    problems = _string_problems([s for _, s, _ in pending], [hw for _, _, hw in pending])
    for (where, _, _), problem in zip(pending, problems, strict=True):
        if problem is not None:
            raise FileFormatError(path, f"{where} {problem}")


def read_coco(path: str | Path, *, max_pixels: int = DEFAULT_MAX_PIXELS) -> CocoSet:
    """Parse a COCO instances file, validating every field (see the module docstring)
    before any mask is decoded: :func:`read_coco_table` as objects.

    Raises:
        FileFormatError: as :func:`read_coco_table`.
    """
    return read_coco_table(path, max_pixels=max_pixels).to_set()


@jsontext.without_gc  # the parsed document is dropped on return
def read_coco_table(path: str | Path, *, max_pixels: int = DEFAULT_MAX_PIXELS) -> CocoTable:
    """Parse a COCO instances file into columns (:class:`CocoTable`), validating every field
    (see the module docstring) before any mask is decoded. A file of plain boxes is checked
    column by column, without an object per annotation.

    Args:
        path: the JSON file.
        max_pixels: largest ``height * width`` an image record may declare.

    Raises:
        FileFormatError: unreadable JSON (too deeply nested, a number of too many digits),
            a missing or mistyped field, an image listed twice, an annotation of an unknown
            image or category, a box or polygon outside its image, an RLE of another size
            or that does not cover the image; the message names the file and the entry
            (``images[k]``, ``annotations[k] (id N)``, ``categories[k]``).
    """
    data = _load_json(path)
    categories = _categories(data.get("categories", []), path)
    records = _images(data["images"], path, max_pixels)
    entries = data.get("annotations", [])
    columns = _box_columns(entries, categories, records)
    if columns is None:  # segmentations, or a problem to name: entry by entry
        columns = _entry_columns(entries, categories, records, path)
    return CocoTable(tuple(records), categories, **columns)


def _entry_columns(entries: list, categories: dict, records: list[dict], path) -> dict:
    """The annotation columns, every entry checked on its own (the first problem named)."""
    images = {rec["id"]: rec for rec in records}
    rows = {rec["id"]: k for k, rec in enumerate(records)}
    seen: dict[int, int] = {}
    pending: list[tuple[str, str, tuple[int, int]]] = []  # compressed RLE, checked together
    out: list[tuple[int, int, CocoAnnotation]] = []
    for k, a in enumerate(entries):
        try:
            image_id, ann, where, string = _annotation(k, a, categories, images, path)
        except FileFormatError:
            _check_strings(pending, path)  # an earlier bad string is reported first
            raise
        out.append((rows[image_id], a["category_id"], ann))
        if string is not None:
            pending.append((where, string, (images[image_id]["height"], images[image_id]["width"])))
        if ann.id != -1 and seen.setdefault(ann.id, k) != k:
            warnings.warn(
                f"{path}: annotations[{seen[ann.id]}] and annotations[{k}] both have id "
                f"{ann.id}; both are kept",
                AnnotationWarning,
                stacklevel=4,
            )
    _check_strings(pending, path)
    n = len(out)
    return {
        "image": np.array([r for r, _, _ in out], np.int64).reshape(n),
        "id": np.array([a.id for _, _, a in out], np.int64).reshape(n),
        "category": np.array([c for _, c, _ in out], np.int64).reshape(n),
        "box": np.array([a.box for _, _, a in out], np.float64).reshape(n, 4),
        "iscrowd": np.array([a.iscrowd for _, _, a in out], bool).reshape(n),
        "area": np.array(
            [np.nan if a.area is None else a.area for _, _, a in out], np.float64
        ).reshape(n),
        "segmentation": tuple(a.segmentation for _, _, a in out),
    }


def segmentation_counts(seg: object, height: int, width: int) -> bytes:
    """A COCO segmentation (polygons, uncompressed or compressed RLE) as the compressed RLE
    string of a ``(height, width)`` mask (decode it with :mod:`torchsar.io.rle`).

    Raises:
        FileFormatError: a segmentation :func:`segmentation_problem` refuses (path ``""``).
    """
    _refuse(segmentation_problems([seg], height, width))
    return _counts(seg, height, width)


def _refuse(problems: list[str | None]) -> None:
    """Raise for the first problem (path ``""``: the caller knows the file)."""
    problem = next((p for p in problems if p is not None), None)
    if problem is not None:
        raise FileFormatError("", problem)


def _counts(seg: object, height: int, width: int) -> bytes:
    """:func:`segmentation_counts` of a segmentation already checked."""
    from pycocotools import mask as mask_utils

    if isinstance(seg, list):
        return mask_utils.merge(mask_utils.frPyObjects(seg, height, width))["counts"]
    if isinstance(seg["counts"], list):
        return mask_utils.frPyObjects(seg, height, width)["counts"]
    return seg["counts"].encode()


def annotation_pixels(
    anns: list[CocoAnnotation], height: int, width: int, *, checked: bool = False
) -> list[np.ndarray]:
    """The flat pixel indices (``row * width + col``) of each annotation's mask (its
    filled box when unsegmented), the run lengths of all decoded at once (``checked``: the
    segmentations were checked already, by :func:`read_coco`).

    Raises:
        FileFormatError: a segmentation :func:`segmentation_problem` refuses (path ``""``).

    Examples:
        >>> a = CocoAnnotation(1, "ship", (1.0, 1.0, 3.0, 2.0), None, False)
        >>> annotation_pixels([a], 4, 4)[0].tolist()
        [5, 9]
    """
    from torchsar.io.rle import counts_from_strings, rle_pixels

    out: list[np.ndarray] = []
    segmented = [k for k, a in enumerate(anns) if a.segmentation is not None]
    if not checked:
        _refuse(segmentation_problems([anns[k].segmentation for k in segmented], height, width))
    strings = [_counts(anns[k].segmentation, height, width) for k in segmented]
    counts, owner = counts_from_strings(strings)
    mask_of, flat = rle_pixels(counts, owner, len(strings), (height, width))
    cuts = np.searchsorted(mask_of, np.arange(1, len(strings)))
    decoded = dict(zip(segmented, np.split(flat, cuts) if strings else [], strict=True))
    for k, a in enumerate(anns):
        if k in decoded:
            out.append(decoded[k])
            continue
        r0, c0, r1, c1 = (
            min(max(round(v), 0), lim)
            for v, lim in zip(a.box, (height, width, height, width), strict=True)
        )
        rr, cc = np.mgrid[r0:r1, c0:c1]
        out.append((rr * width + cc).reshape(-1))
    return out


def annotation_mask(ann: CocoAnnotation, height: int, width: int) -> np.ndarray:
    """The ``(height, width)`` bool mask of an annotation; its filled box if unsegmented.

    Polygons (a list of ``[x0, y0, x1, y1, ...]``), uncompressed RLE (``counts`` a list) and
    compressed RLE (``counts`` a string) are decoded by ``pycocotools.mask``.

    Raises:
        FileFormatError: a segmentation :func:`segmentation_problem` refuses (path ``""``).
    """
    from pycocotools import mask as mask_utils

    seg = ann.segmentation
    if seg is None:
        out = np.zeros((height, width), bool)
        r0, c0, r1, c1 = (round(v) for v in ann.box)
        out[r0:r1, c0:c1] = True
        return out
    rle = {"size": [height, width], "counts": segmentation_counts(seg, height, width)}
    with warnings.catch_warnings():  # pycocotools' decoder predates numpy 2's copy keyword
        warnings.simplefilter("ignore", DeprecationWarning)
        m = mask_utils.decode(rle)
    return np.asarray(m, dtype=bool)
