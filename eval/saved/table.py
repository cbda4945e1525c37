"""Saved predictions as one table: a row per prediction, referring to its image by COCO id
or by name, and the readers of the COCO results and point CSV formats.

- COCO results JSON (what ``pycocotools``' ``loadRes`` reads, and what
  ``torchsar-eval run --export-coco`` writes): a list of ``{"image_id", "score", "bbox":
  [x, y, w, h]}`` and/or ``"segmentation"`` (polygons or RLE), optional ``"category_id"``;
  ``"file_name"`` may stand for ``"image_id"``. The IoU type is ``segm`` when every row has
  a segmentation, else ``bbox`` (or as asked).
- Point CSV (centroid detectors, xView3-SAR style): one row per detection with an image
  column (``image``, ``file_name``, ``image_id`` or ``scene_id``), ``row`` and ``col``
  (or ``detect_scene_row`` / ``detect_scene_column``), optional ``score`` (1 when absent),
  ``length_m`` (or ``vessel_length_m``) and ``class``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from torchsar.io import jsontext
from torchsar_eval.errors import EvalError

__all__ = ["IOU_TYPES", "PredictionTable", "read_coco_results", "read_points"]

IOU_TYPES = ("auto", "bbox", "segm")


@dataclass(frozen=True)
class PredictionTable:
    """Predictions of one file.

    Attributes:
        path: the file.
        refs: ``(N,)`` object array: each row's image, a COCO id (int) or a name (str).
        score: float64 ``(N,)``.
        geometry: ``"mask"`` (``segmentation``), ``"box"`` (``box``) or ``"point"``.
        box: float64 ``(N, 4)`` ``(r0, c0, r1, c1)`` (boxes and masks' boxes).
        segmentation: the rows' COCO segmentations (``geometry == "mask"``), else ``None``.
        point: float64 ``(N, 2)`` (row, col) for points, else ``None``.
        classes: ``(N,)`` object array of class names, or ``None``.
        length_m: float64 ``(N,)`` lengths in metres (NaN unknown), or ``None``.
        declared_area: float64 ``(N,)`` the areas pycocotools reads for COCO's area ranges
            (a results file whose first entry has a ``bbox``: ``w * h`` of every entry's,
            even for masks; NaN: the object's own area), or ``None``.
    """

    path: Path
    refs: np.ndarray
    score: np.ndarray
    geometry: str
    box: np.ndarray
    segmentation: list | None = None
    point: np.ndarray | None = None
    classes: np.ndarray | None = None
    length_m: np.ndarray | None = None
    declared_area: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.score.size)


def _fail(path: Path, message: str) -> EvalError:
    return EvalError(f"predictions {path}: {message}")


def _number(value: object, path: Path, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or math.isnan(value):
        raise _fail(path, f"{what} must be a number, got {value!r:.40}")
    return float(value)


def _coco_row(row: object, k: int, path: Path) -> tuple:
    if not isinstance(row, dict):
        raise _fail(path, f"entry {k} is not an object: {row!r:.60}")
    ref = row.get("image_id", row.get("file_name"))
    if "image_id" in row and (isinstance(ref, bool) or not isinstance(ref, int)):
        raise _fail(
            path,
            f"entry {k} image_id {ref!r:.40} is not an integer id (an image's "
            "name goes in file_name)",
        )
    if isinstance(ref, bool) or not isinstance(ref, int | str):
        raise _fail(path, f"entry {k} has no image_id (an integer) or file_name")
    score = _number(row.get("score"), path, f"entry {k} score")
    box = row.get("bbox")
    if box is not None:
        if not isinstance(box, list) or len(box) != 4:
            raise _fail(path, f"entry {k} bbox must be [x, y, width, height]")
        x, y, w, h = (_number(v, path, f"entry {k} bbox") for v in box)
        if w < 0 or h < 0 or not all(map(math.isfinite, (x, y, w, h))):
            raise _fail(path, f"entry {k} bbox {box} has a negative or infinite side")
        box = (y, x, y + h, x + w)
    seg = row.get("segmentation")
    if seg is not None and not isinstance(seg, list | dict):
        raise _fail(path, f"entry {k} segmentation must be polygons or RLE")
    return ref, score, box, seg, row.get("category_id")


def _plain_box_rows(data: list, path: Path) -> PredictionTable | None:
    """The table of a results list whose every entry is ``{"image_id": int, "bbox": [4
    finite numbers, w, h >= 0], "score": number, "category_id"?: int}`` without
    segmentation (the checks of :func:`_coco_row`, made at once), else ``None``: the
    entry-by-entry path then names the first problem."""
    if not set(map(type, data)) <= {dict} or any("segmentation" in r for r in data):
        return None
    try:
        refs = [r["image_id"] for r in data]
        scores = [r["score"] for r in data]
        boxes = [r["bbox"] for r in data]
    except KeyError:
        return None
    cats = [r.get("category_id") for r in data]
    numbers = {int, float}  # (bool is neither; checked type by type, at C speed)
    if (
        not set(map(type, refs)) <= {int}
        or not set(map(type, scores)) <= numbers
        or not jsontext.plain_boxes(boxes)
    ):
        return None
    try:
        score = np.array(scores, dtype=np.float64)
        box = np.array(boxes, dtype=np.float64).reshape(len(data), 4)
    except OverflowError:  # an integer past float range
        return None
    if not np.isfinite(box).all() or (box[:, 2:] < 0).any() or np.isnan(score).any():
        return None
    n = len(data)
    x, y, w, h = box.T
    with np.errstate(over="ignore"):  # a finite box past float range: inf, as pycocotools
        rc = np.stack([y, x, y + h, x + w], axis=1).reshape(n, 4)
        area = w * h
    return PredictionTable(
        path=path,
        refs=np.array(refs, dtype=object).reshape(n),
        score=score.reshape(n),
        geometry="box",
        box=rc,
        classes=None
        if all(c is None for c in cats)
        else np.array([str(c) for c in cats], dtype=object),
        declared_area=area if n else None,
    )


@jsontext.without_gc  # the parsed document is dropped on return
def read_coco_results(path: str | Path, iou_type: str = "auto") -> PredictionTable:
    """Read a COCO results file (see the module docstring).

    Raises:
        EvalError: not a JSON list, an entry without image, score, bbox or segmentation, a
            bad box; names the file and the entry.
    """
    path = Path(path)
    if iou_type not in IOU_TYPES:
        raise EvalError(f"iou_type must be one of {', '.join(IOU_TYPES)}, got {iou_type!r}")
    try:
        data = jsontext.read_json(path)  # (collector paused for the whole read)
    except RecursionError:
        raise _fail(path, "is not a readable JSON file (nested too deeply)") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:  # ValueError: too many digits
        raise _fail(path, f"is not a readable JSON file ({str(exc)[:200]})") from None
    if isinstance(data, dict) and "annotations" in data and "images" in data:
        raise _fail(
            path,
            "is a COCO ground-truth file: give it as --dataset coco:FILE and the "
            "detections as a results list [{image_id, bbox, score}, ...]",
        )
    if not isinstance(data, list):
        raise _fail(path, "is not a COCO results list [{image_id, bbox|segmentation, score}]")
    fast = _plain_box_rows(data, path) if iou_type != "segm" else None
    if fast is not None:  # every entry a plain valid box: checked all at once
        return fast
    rows = [_coco_row(r, k, path) for k, r in enumerate(data)]
    has_seg = all(r[3] is not None for r in rows) and bool(rows)
    has_box = all(r[2] is not None for r in rows)
    if iou_type == "auto":
        iou_type = "segm" if has_seg else "bbox"
    if (iou_type == "segm" and not has_seg) or (iou_type == "bbox" and not has_box):
        what = "segmentation" if iou_type == "segm" else "bbox"
        raise _fail(path, f"iou_type {iou_type} needs a {what} in every entry")
    n = len(rows)
    box = np.array(
        [r[2] if r[2] is not None else (np.nan,) * 4 for r in rows], dtype=np.float64
    ).reshape(n, 4)
    cats = [r[4] for r in rows]
    area = None
    if rows and rows[0][2] is not None:  # pycocotools' loadRes: the bbox branch, w * h
        with np.errstate(over="ignore", invalid="ignore"):
            area = (box[:, 2] - box[:, 0]) * (box[:, 3] - box[:, 1])
    return PredictionTable(
        path=path,
        refs=np.array([r[0] for r in rows], dtype=object).reshape(n),
        score=np.array([r[1] for r in rows], dtype=np.float64).reshape(n),
        geometry="mask" if iou_type == "segm" else "box",
        box=box,
        segmentation=[r[3] for r in rows] if iou_type == "segm" else None,
        classes=None
        if all(c is None for c in cats)
        else np.array([str(c) for c in cats], dtype=object),
        declared_area=area,
    )


_IMAGE = ("image", "file_name", "image_id", "scene_id")
_ROW = ("row", "detect_scene_row")
_COL = ("col", "detect_scene_column")
_LENGTH = ("length_m", "vessel_length_m")


def _column(df: pd.DataFrame, names: tuple[str, ...], path: Path, required: bool = True):
    for n in names:
        if n in df.columns:
            return df[n]
    if required:
        cols = ", ".join(str(c)[:40] for c in list(df.columns)[:20])
        raise _fail(path, f"has no column {' or '.join(names)} (columns: {cols})")
    return None


def _floats(col: pd.Series, path: Path, what: str, *, finite: bool = True) -> np.ndarray:
    try:
        values = pd.to_numeric(col, errors="coerce").to_numpy(np.float64)
    except OverflowError:  # an integer of hundreds of digits: not a coordinate or score
        values = np.array([_float_or_nan(v) for v in col], np.float64).reshape(len(col))
    bad = np.isnan(values) if finite else np.zeros(values.size, bool)
    bad |= np.isinf(values) if finite else False
    bad |= ~pd.isna(col).to_numpy() & np.isnan(values)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise _fail(path, f"row {k + 2}: {what} {str(col.iloc[k])[:40]!r} is not a finite number")
    return values


def _float_or_nan(value: object) -> float:
    try:
        return float(value)
    except (OverflowError, ValueError, TypeError):
        return float("nan")


def _refs(df: pd.DataFrame, path: Path) -> np.ndarray:
    """Each row's image: an integer id from an ``image_id`` column, else a name (text)."""
    col = next((n for n in _IMAGE if n in df.columns), None)
    values = _column(df, _IMAGE, path)
    if col != "image_id":
        return values.astype(str).to_numpy(dtype=object)
    text = [str(v).strip() for v in values.tolist()]
    bad = [k for k, v in enumerate(text) if not (v.isascii() and v.isdigit() and len(v) <= 18)]
    if bad:
        k = bad[0]
        raise _fail(
            path,
            f"row {k + 2}: image_id {text[k][:40]!r} is not an integer id "
            "(an image's name goes in an image or file_name column)",
        )
    return np.array([int(v) for v in text], dtype=object).reshape(len(text))


def read_points(path: str | Path) -> PredictionTable:
    """Read a point CSV (see the module docstring).

    Raises:
        EvalError: unreadable CSV, a missing column, a non-numeric coordinate or score.
    """
    path = Path(path)
    try:
        df = pd.read_csv(path, dtype={n: str for n in _IMAGE})
    except (OSError, UnicodeDecodeError, pd.errors.ParserError) as exc:
        raise _fail(path, f"is not a readable CSV file ({exc})") from None
    except pd.errors.EmptyDataError:
        raise _fail(path, "is empty (expected a header image,row,col,score)") from None
    refs = _refs(df, path)
    point = np.stack(
        [
            _floats(_column(df, _ROW, path), path, "row"),
            _floats(_column(df, _COL, path), path, "col"),
        ],
        axis=1,
    )
    score_col = _column(df, ("score",), path, required=False)
    score = np.ones(len(df)) if score_col is None else _floats(score_col, path, "score")
    length_col = _column(df, _LENGTH, path, required=False)
    length = None if length_col is None else _floats(length_col, path, "length", finite=False)
    if length is not None and ((length < 0) | np.isinf(length)).any():
        k = int(np.flatnonzero((length < 0) | np.isinf(length))[0])
        raise _fail(
            path,
            f"row {k + 2}: length {length[k]:g} is not a length in metres "
            "(a non-negative number, or empty when unknown)",
        )
    cls = _column(df, ("class",), path, required=False)
    return PredictionTable(
        path=path,
        refs=refs,
        score=score,
        geometry="point",
        box=np.concatenate([point + 0.5, point + 0.5], axis=1),
        point=point,
        classes=None if cls is None else cls.astype(str).to_numpy(dtype=object),
        length_m=length,
    )
