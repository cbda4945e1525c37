"""Saved predictions as a detector: read once, bound to a dataset (every prediction must
refer to one of its images), then called batch by batch like any detector.

Worker processes receive the file's path and the row -> item map, and read the file again
(once per process), so a large file is never pickled per shard.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
from torch import Tensor
from torch.utils.data import Dataset

from torchsar.detection import Detection
from torchsar.io.coco import segmentation_problems
from torchsar.io.errors import FileFormatError
from torchsar.io.raster import check_regular_file
from torchsar.io.rle import counts_from_strings, rle_pixels
from torchsar.objects import Objects
from torchsar_eval.datasets.manifest import file_manifest
from torchsar_eval.detector import Detector
from torchsar_eval.errors import EvalError
from torchsar_eval.saved.keys import dataset_keys, locate
from torchsar_eval.saved.masks import MaskFolder
from torchsar_eval.saved.table import (
    IOU_TYPES,
    PredictionTable,
    read_coco_results,
    read_points,
)

__all__ = ["FORMATS", "SavedPredictions", "predictions"]

FORMATS = ("auto", "coco", "points", "masks")

_TABLES: dict[tuple, PredictionTable] = {}
"""Tables read in this process, by (path, size, mtime, format, iou_type)."""


IDS = ("name", "position")
"""How integer image ids are read on a dataset without ids (:class:`SavedPredictions`)."""


def _format(path: Path, fmt: str) -> str:
    if fmt not in FORMATS:
        raise EvalError(f"predictions format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if not path.exists():
        raise EvalError(f"predictions {path} do not exist")
    if fmt != "auto":
        return fmt
    if path.is_dir():
        return "masks"
    suffix = path.suffix.lower()
    if suffix == ".json":
        return "coco"
    if suffix in (".csv", ".txt"):
        return "points"
    raise EvalError(
        f"predictions {path}: cannot tell the format from the name: give "
        "format='coco' (JSON), 'points' (CSV) or 'masks' (a folder)"
    )


def _read(path: Path, fmt: str, iou_type: str, digest: str) -> PredictionTable | MaskFolder:
    """The file's table (cached by its content's ``digest``: never a stale copy)."""
    if fmt == "masks":
        return MaskFolder(path)
    key = (str(path.resolve()), digest, fmt, iou_type)
    if key not in _TABLES:
        _TABLES[key] = read_coco_results(path, iou_type) if fmt == "coco" else read_points(path)
    return _TABLES[key]


def _digest(path: Path, fmt: str) -> str:
    """The sha256 of a predictions file's bytes; of a mask folder, of its files' names,
    sizes and modification times."""
    if fmt == "masks":
        files = sorted(p for p in path.rglob("*") if p.is_file())
        return file_manifest(path, files)["sha256_mtime"]
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def compressed_counts(seg: object, h: int, w: int) -> bytes:
    """A COCO segmentation (polygons, RLE or compressed RLE) as the compressed RLE string of
    an ``(h, w)`` mask."""
    # pycocotools only for COCO segmentations (boxes never load it)
    from pycocotools import mask as mask_utils

    if isinstance(seg, list):
        return mask_utils.merge(mask_utils.frPyObjects(seg, h, w))["counts"]
    if isinstance(seg.get("counts"), list):
        return mask_utils.frPyObjects(seg, h, w)["counts"]
    size = seg.get("size")
    if size is not None and list(size) != [h, w]:
        raise EvalError(f"a segmentation of size {size} on an image of {h}x{w}")
    counts = seg["counts"]
    return counts.encode() if isinstance(counts, str) else counts


def segmentation_pixels(
    segs: list, h: int, w: int, entries: list | None = None, path: Path | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(mask index, flat row-major index)`` of the pixels of COCO segmentations of one
    image size, decoded from their run lengths without dense masks.

    Each is checked first (:func:`torchsar.io.coco.segmentation_problems`; a predicted
    polygon may reach outside the image by up to the image's size, as a detector's output
    at the border can, but not further, so no coordinate makes the decoder allocate
    without bound); a bad one raises :class:`EvalError` naming ``path`` and its entry
    number (from ``entries``).
    """
    for k, problem in enumerate(segmentation_problems(segs, h, w, tolerance=max(h, w))):
        if problem is not None:
            entry = entries[k] if entries is not None else k
            raise EvalError(f"predictions {path}: entry {entry} {problem}")
    counts, owner = counts_from_strings([compressed_counts(s, h, w) for s in segs])
    return rle_pixels(counts, owner, len(segs), (h, w))


def _class_names(
    classes: np.ndarray | None, dataset: Dataset, what: str, rows: np.ndarray
) -> np.ndarray | None:
    """Class names of the rows: COCO category ids named by the dataset's categories (a
    ``coco:`` dataset; an id it does not list is refused); on other datasets, ids that are
    all 1 (what ``--export-coco`` writes for class-agnostic detectors) mean class-agnostic.

    Raises:
        EvalError: a row's category id is not one of the dataset's (naming the entry).
    """
    if classes is None:
        return None
    known = getattr(dataset, "categories", None)
    if known:
        ids = {str(k): v for k, v in known.items()}
        bad = [k for k, c in enumerate(classes.tolist()) if c not in ids]
        if bad:
            k = int(rows[bad[0]]) if rows.size else bad[0]
            listed = ", ".join(f"{i} ({n})" for i, n in sorted(known.items()))
            raise EvalError(
                f"{what}: entry {k} has category_id {classes[bad[0]]}, which the "
                f"dataset does not list (its categories: {listed}); "
                f"{len(bad)} entries have unknown ids"
            )
        return np.array([ids[c] for c in classes.tolist()], dtype=object)
    return None if set(classes.tolist()) <= {"1"} else classes


class SavedPredictions:
    """The predictions in one file, to bind to a dataset (:meth:`bind`) before use. They
    read no pixel (``needs_images``): a run of saved predictions only decodes the ground
    truth.

    Args:
        path: a COCO results JSON, a point CSV or a folder of per-image masks.
        format: ``"auto"`` (by the name), ``"coco"``, ``"points"`` or ``"masks"``.
        iou_type: COCO results: ``"auto"`` (``segm`` when every entry has a
            segmentation), ``"bbox"`` or ``"segm"``.
        threshold: operating threshold of the scores (needed by score-map masks).
        ids: how integer image ids are read on a dataset without ids of its own: refused
            (``"name"``: give names), or 1-based positions in dataset order
            (``"position"``). On a ``coco:`` dataset ids are its COCO ids either way.
    """

    reads_only = True  # (the detector harness passes it the batch itself)

    def __init__(
        self,
        path: str | Path,
        *,
        format: str = "auto",
        iou_type: str = "auto",
        threshold: float | None = None,
        ids: str = "name",
    ) -> None:
        self.path = Path(path)
        if ids not in IDS:
            raise EvalError(f"ids must be one of {', '.join(IDS)}, got {ids!r}")
        self.ids = ids
        self.format = _format(self.path, format)
        if iou_type not in IOU_TYPES:
            raise EvalError(f"iou_type must be one of {', '.join(IOU_TYPES)}, got {iou_type!r}")
        self.iou_type, self.threshold = iou_type, threshold
        self.needs_images = False
        self.saved_predictions = True  # no detection time: the timing table says so
        if self.format != "masks":  # a FIFO or a device would block: refused unopened
            try:
                check_regular_file(self.path)
            except FileFormatError as exc:
                raise EvalError(f"predictions {exc}") from None
        self.digest = _digest(self.path, self.format)  # what a resumed run must find again
        self.table = _read(self.path, self.format, iou_type, self.digest)  # errors before work
        self._item_rows: tuple[np.ndarray, np.ndarray] | None = None

    def bind(self, dataset: Dataset, name: str) -> SavedPredictions:
        """These predictions with each row's dataset item (every row must have one)."""
        bound = SavedPredictions.__new__(SavedPredictions)
        bound.__dict__.update(self.__dict__)
        what = f"predictions {self.path} on dataset {name}"
        place = getattr(dataset, "locate_points", None)
        bound._point_offset = None
        if place is not None and getattr(self.table, "geometry", None) == "point":
            # whole-scene points (scene: datasets): each goes to the chip holding it
            items, bound._point_offset = place(self.table.refs, self.table.point, what)
        else:
            items = locate(
                self.table.refs,
                dataset_keys(dataset),
                what,
                positions=getattr(self, "ids", "name") == "position",
            )
        order = np.argsort(items, kind="stable")
        bound._item_rows = (items[order], order)
        bound._classes = _class_names(
            getattr(self.table, "classes", None), dataset, what, np.arange(len(items))
        )
        return bound

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["table"] = None  # read again by each process
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        if _digest(self.path, self.format) != self.digest:
            raise EvalError(
                f"predictions {self.path} changed during the run (a worker read "
                "other contents than the run did); run again"
            )
        self.table = _read(self.path, self.format, self.iou_type, self.digest)

    def rows_of(self, item: int) -> np.ndarray:
        """The rows of dataset item ``item``, in file order."""
        return self.rows_for([item])[0]

    def rows_for(self, items) -> tuple[np.ndarray, np.ndarray]:
        """``(rows, counts)``: the rows of dataset items ``items`` item after item (each
        item's in file order), and how many each has."""
        if self._item_rows is None:
            raise EvalError(f"predictions {self.path} are not bound to a dataset")
        sorted_items, order = self._item_rows
        want = np.asarray(items, np.int64).reshape(-1)
        lo = np.searchsorted(sorted_items, want)
        hi = np.searchsorted(sorted_items, want + 1)
        counts = hi - lo
        pos = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
        return order[np.repeat(lo, counts) + pos], counts

    def __call__(self, images: Tensor, meta: list[dict]) -> Objects | Detection:
        b, c, h, w = images.shape
        rows = [self.rows_of(int(m["index"])) for m in meta]
        if isinstance(self.table, MaskFolder):
            return self.table.batch(rows, (b, c, h, w), self.threshold)
        plane = np.concatenate([np.full(r.size, k * c, np.int64) for k, r in enumerate(rows)])
        r = np.concatenate(rows) if rows else np.zeros(0, np.int64)
        t = self.table
        names = getattr(self, "_classes", None)
        classes = None if names is None else names[r]
        common = {"plane": plane, "planes": b * c, "classes": classes}
        area = None if t.declared_area is None else t.declared_area[r]
        if t.geometry == "mask":
            owner, pixels = segmentation_pixels(
                [t.segmentation[i] for i in r], h, w, r.tolist(), self.path
            )
            obj = Objects.from_pixels(owner, pixels, t.score[r], shape=(h, w), **common)
            return obj.with_declared_area(area)
        if t.geometry == "box":
            obj = Objects.from_boxes(t.box[r], t.score[r], shape=(h, w), **common)
            return obj.with_declared_area(area)
        length = None if t.length_m is None else t.length_m[r]
        offset = getattr(self, "_point_offset", None)
        point = t.point[r] if offset is None else t.point[r] - offset[r]
        return Objects.from_points(point, t.score[r], shape=(h, w), length_m=length, **common)


def predictions(
    path: str | Path,
    *,
    name: str | None = None,
    format: str = "auto",
    iou_type: str = "auto",
    threshold: float | None = None,
    instances: str = "auto",
    ids: str = "name",
) -> Detector:
    """Saved predictions as a detector for :func:`torchsar_eval.evaluate`.

    Args:
        path: a COCO results JSON (``[{image_id, bbox, segmentation, score}]``), a point
            CSV (``image,row,col,score[,length_m]``) or a folder of per-image masks
            (``<image>.png|.npy|.tif``: integer instance ids with optional
            ``<image>.scores.json`` ``{"id": score}``, or a float score map).
        name: the row name (default: the file's stem).
        format, iou_type: see :class:`SavedPredictions`.
        threshold: the operating threshold of the scores (``None``: every prediction
            counts at the operating point; choose one with a calibration instead).
        instances: ``"discriminate"`` sends mask predictions through the discrimination
            stage instead of scoring them as they are.
        ids: ``"position"``: integer image ids are 1-based positions in the dataset's order
            (on a dataset without ids; see :class:`SavedPredictions`).

    Examples:
        >>> import json, tempfile, pathlib
        >>> f = pathlib.Path(tempfile.mkdtemp()) / "dets.json"
        >>> _ = f.write_text(json.dumps([{"image_id": 1, "bbox": [2, 3, 4, 5], "score": 0.9}]))
        >>> d = predictions(f, threshold=0.5)
        >>> d.name, d.threshold
        ('dets', 0.5)
    """
    saved = SavedPredictions(path, format=format, iou_type=iou_type, threshold=threshold, ids=ids)
    opts = {"path": str(path), "format": saved.format}
    if ids != "name":
        opts["ids"] = ids
    if saved.format == "coco":
        opts["iou_type"] = (saved.table.geometry == "mask" and "segm") or "bbox"
    return Detector(
        name or Path(path).stem,
        saved,
        opts,
        threshold=threshold,
        instances=instances,
        call_options={},
    )
