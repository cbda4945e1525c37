"""COCO instance annotations: images, categories, boxes, polygons and RLE masks.

Masks are decoded with ``pycocotools`` (polygons, uncompressed and compressed RLE). Boxes
are COCO ``[x, y, width, height]`` and are returned as ``(r0, c0, r1, c1)`` end-exclusive.
Crowd annotations (``iscrowd=1``) are kept apart so callers can make them don't-care.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from torchsar.io.errors import FileFormatError
from torchsar.io.raster import check_regular_file

__all__ = [
    "CocoAnnotation",
    "CocoImage",
    "CocoSet",
    "annotation_mask",
    "annotation_pixels",
    "read_coco",
    "segmentation_counts",
]


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


def _load_json(path: str | Path) -> dict:
    """The top-level object of a COCO file, or an error naming it."""
    check_regular_file(path)
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise FileFormatError(path, f"is not a readable JSON file ({exc})") from exc
    if not isinstance(data, dict) or not isinstance(data.get("images"), list):
        raise FileFormatError(path, "is not a COCO annotation file (no 'images' list)")
    return data


def _annotation(a: dict, categories: dict[int, str], image: dict, path) -> CocoAnnotation:
    """Validate one annotation against its image (category known, box inside)."""
    aid = a.get("id")
    if a.get("category_id") not in categories:
        raise FileFormatError(
            path, f"annotation {aid} has unknown category_id {a.get('category_id')!r}"
        )
    try:
        x, y, w, h = (float(v) for v in a["bbox"])
    except (KeyError, TypeError, ValueError):
        raise FileFormatError(path, f"annotation {aid} has no valid bbox [x, y, w, h]") from None
    H, W = image["height"], image["width"]
    if w < 0 or h < 0 or x < 0 or y < 0 or x + w > W + 1e-6 or y + h > H + 1e-6:
        raise FileFormatError(
            path,
            f"annotation {aid} box [x={x:g}, y={y:g}, w={w:g}, h={h:g}] lies outside image "
            f"{image['file_name']} ({W}x{H})",
        )
    return CocoAnnotation(
        int(aid) if aid is not None else -1,
        categories[a["category_id"]],
        (y, x, y + h, x + w),
        a.get("segmentation") or None,
        bool(a.get("iscrowd", 0)),
        float(a["area"]) if isinstance(a.get("area"), int | float) else None,
    )


def _image(im: dict, path) -> dict:
    """Validate an image record (id, file_name, positive height and width)."""
    try:
        rec = {
            "id": int(im["id"]),
            "file_name": str(im["file_name"]),
            "height": int(im["height"]),
            "width": int(im["width"]),
        }
    except (KeyError, TypeError, ValueError):
        raise FileFormatError(
            path, f"image record {im!r:.80} lacks id/file_name/height/width"
        ) from None
    if rec["height"] <= 0 or rec["width"] <= 0:
        raise FileFormatError(path, f"image {rec['file_name']} has size {rec['width']}x0")
    return rec


def read_coco(path: str | Path) -> CocoSet:
    """Parse a COCO instances file, validating every annotation.

    Raises:
        FileFormatError: unreadable JSON, missing fields, an annotation of an unknown image
            or category, or a box outside its image.
    """
    data = _load_json(path)
    categories = {c["id"]: str(c["name"]) for c in data.get("categories", [])}
    images = {}
    for im in data["images"]:
        rec = _image(im, path)
        images[rec["id"]] = (rec, [])
    for a in data.get("annotations", []):
        if a.get("image_id") not in images:
            raise FileFormatError(
                path, f"annotation {a.get('id')} refers to unknown image_id {a.get('image_id')}"
            )
        rec, anns = images[a["image_id"]]
        anns.append(_annotation(a, categories, rec, path))
    return CocoSet(
        tuple(CocoImage(**rec, annotations=tuple(anns)) for rec, anns in images.values()),
        categories,
    )


def segmentation_counts(seg: object, height: int, width: int) -> bytes:
    """A COCO segmentation (polygons, uncompressed or compressed RLE) as the compressed RLE
    string of a ``(height, width)`` mask (decode it with :mod:`torchsar.io.rle`).

    Raises:
        FileFormatError: an RLE whose ``size`` is not ``[height, width]`` (path ``""``).
    """
    from pycocotools import mask as mask_utils

    if isinstance(seg, list):
        return mask_utils.merge(mask_utils.frPyObjects(seg, height, width))["counts"]
    if isinstance(seg.get("counts"), list):
        return mask_utils.frPyObjects(seg, height, width)["counts"]
    size = seg.get("size")
    if size is not None and [int(v) for v in size] != [height, width]:
        raise FileFormatError("", f"a segmentation of size {size} on an image of "
                              f"{height}x{width}")  # fmt: skip
    counts = seg["counts"]
    return counts.encode() if isinstance(counts, str) else bytes(counts)


def annotation_pixels(anns: list[CocoAnnotation], height: int, width: int) -> list[np.ndarray]:
    """The flat pixel indices (``row * width + col``) of each annotation's mask (its
    filled box when unsegmented), the run lengths of all decoded at once.

    Example:
        >>> a = CocoAnnotation(1, "ship", (1.0, 1.0, 3.0, 2.0), None, False)
        >>> annotation_pixels([a], 4, 4)[0].tolist()
        [5, 9]
    """
    from torchsar.io.rle import counts_from_strings, rle_pixels

    out: list[np.ndarray] = []
    segmented = [k for k, a in enumerate(anns) if a.segmentation is not None]
    strings = [segmentation_counts(anns[k].segmentation, height, width) for k in segmented]
    counts, owner = counts_from_strings(strings)
    mask_of, flat = rle_pixels(counts, owner, len(strings), (height, width))
    cuts = np.searchsorted(mask_of, np.arange(1, len(strings)))
    decoded = dict(zip(segmented, np.split(flat, cuts) if strings else [], strict=True))
    for k, a in enumerate(anns):
        if k in decoded:
            out.append(decoded[k])
            continue
        r0, c0, r1, c1 = (min(max(round(v), 0), lim) for v, lim in
                          zip(a.box, (height, width, height, width), strict=True))  # fmt: skip
        rr, cc = np.mgrid[r0:r1, c0:c1]
        out.append((rr * width + cc).reshape(-1))
    return out


def annotation_mask(ann: CocoAnnotation, height: int, width: int) -> np.ndarray:
    """The ``(height, width)`` bool mask of an annotation; its filled box if unsegmented.

    Polygons (a list of ``[x0, y0, x1, y1, ...]``), uncompressed RLE (``counts`` a list) and
    compressed RLE (``counts`` a string) are decoded by ``pycocotools.mask``.
    """
    from pycocotools import mask as mask_utils

    seg = ann.segmentation
    if seg is None:
        out = np.zeros((height, width), bool)
        r0, c0, r1, c1 = (round(v) for v in ann.box)
        out[r0:r1, c0:c1] = True
        return out
    if isinstance(seg, list):
        rle = mask_utils.merge(mask_utils.frPyObjects(seg, height, width))
    elif isinstance(seg.get("counts"), list):
        rle = mask_utils.frPyObjects(seg, height, width)
    else:
        rle = dict(
            seg, counts=seg["counts"].encode() if isinstance(seg["counts"], str) else seg["counts"]
        )
    with warnings.catch_warnings():  # pycocotools' decoder predates numpy 2's copy keyword
        warnings.simplefilter("ignore", DeprecationWarning)
        m = mask_utils.decode(rle)
    return np.asarray(m if m.ndim == 2 else m.any(axis=2), dtype=bool)
