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

__all__ = ["CocoAnnotation", "CocoImage", "CocoSet", "annotation_mask", "read_coco"]


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
