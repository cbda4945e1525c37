"""Pascal VOC XML annotations (boxes), as used by SSDD.

VOC ``bndbox`` corners ``xmin, ymin, xmax, ymax`` are 1-based and inclusive; they are
returned as 0-based end-exclusive ``(r0, c0, r1, c1) = (ymin - 1, xmin - 1, ymax, xmax)``.
The ``<size>`` must give positive integer ``<height>`` and ``<width>`` (``600`` or ``600.0``)
of at most ``max_pixels`` pixels, and every corner a finite number inside the image.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from torchsar.io.errors import FileFormatError
from torchsar.io.raster import DEFAULT_MAX_PIXELS, check_regular_file

__all__ = ["VocAnnotation", "VocObject", "read_voc"]


@dataclass(frozen=True)
class VocObject:
    """One box: class ``name``, ``box`` ``(r0, c0, r1, c1)``, VOC ``difficult`` flag."""

    name: str
    box: tuple[float, float, float, float]
    difficult: bool


@dataclass(frozen=True)
class VocAnnotation:
    """One annotation file: the image it describes, its size and its objects."""

    filename: str
    height: int
    width: int
    objects: tuple[VocObject, ...]


def _show(text: str | None) -> str:
    return repr(text if text is None or len(text) <= 40 else text[:37] + "...")


def _number(node: ET.Element, tag: str, path, what: str) -> float:
    """A finite numeric child ``tag`` of ``node`` or an error naming the file and tag."""
    text = node.findtext(tag)
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise FileFormatError(path, f"{what} has no numeric <{tag}> (got {_show(text)})") from None
    if not math.isfinite(value):
        raise FileFormatError(path, f"{what} <{tag}> {_show(text)} is not a finite number")
    return value


def _dimension(size: ET.Element, tag: str, path) -> int:
    """A positive integer ``<height>`` or ``<width>`` of ``<size>``."""
    text = size.findtext(tag)
    try:
        value = float(text)
    except (TypeError, ValueError):
        value = math.nan
    if not (math.isfinite(value) and value > 0 and value.is_integer()):
        raise FileFormatError(
            path, f"<size> <{tag}> {_show(text and text.strip())} must be a positive integer"
        )
    return int(value)


def _object(node: ET.Element, height: int, width: int, path) -> VocObject:
    """One ``<object>``: name, difficult flag, box checked against the image size."""
    box = node.find("bndbox")
    name = (node.findtext("name") or "").strip()
    if box is None or not name:
        raise FileFormatError(path, "an <object> lacks <name> or <bndbox>")
    what = f"box of {name!r}"
    x0, y0, x1, y1 = (_number(box, t, path, what) for t in ("xmin", "ymin", "xmax", "ymax"))
    r = (y0 - 1, x0 - 1, y1, x1)
    if not (0 <= r[0] < r[2] <= height and 0 <= r[1] < r[3] <= width):
        raise FileFormatError(
            path,
            f"box of {name!r} (xmin={x0:g}, ymin={y0:g}, xmax={x1:g}, ymax={y1:g}) lies "
            f"outside the {width}x{height} image or is empty",
        )
    return VocObject(name, r, (node.findtext("difficult") or "0").strip() == "1")


def read_voc(path: str | Path, *, max_pixels: int = DEFAULT_MAX_PIXELS) -> VocAnnotation:
    """Parse one VOC XML file.

    Args:
        path: the XML file.
        max_pixels: largest ``height * width`` its ``<size>`` may declare.

    Raises:
        FileFormatError: unparsable XML, missing size, filename or box fields, a size that
            is not positive integers or is over ``max_pixels``, a corner that is not a
            finite number, a box outside the image.
    """
    check_regular_file(path)
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError, ValueError, RecursionError) as exc:
        raise FileFormatError(path, f"is not a readable VOC XML file ({exc})") from exc
    size = root.find("size")
    filename = (root.findtext("filename") or "").strip()
    if size is None or not filename:
        raise FileFormatError(path, "VOC annotation lacks <filename> or <size>")
    h, w = _dimension(size, "height", path), _dimension(size, "width", path)
    if h * w > max_pixels:
        raise FileFormatError(
            path,
            f"<size> is {w}x{h} = {w * h:,} pixels, over the limit of {max_pixels:,} "
            "(raise it with max_pixels)",
        )
    objects = tuple(_object(o, h, w, path) for o in root.iter("object"))
    return VocAnnotation(filename, h, w, objects)
