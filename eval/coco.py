"""COCO export of a run: ground truth (``instances`` format) and each detector's detections
(results format with scores), so anyone can re-score a run with ``pycocotools``.

Boxes are ``[x, y, width, height]`` in pixels, masks run-length encoded (point objects
carry ``"point": [x, y]`` and a zero-size box). A plane's ignore pixels become one
``iscrowd`` annotation. Image ids are the planes' positions in the dataset, counted from 1
(item ``i``'s channel ``c`` of ``C`` is ``i * C + c + 1``), so the ids do not depend on the
shards and saved predictions that use them find their images again. Class-agnostic
detections carry the first category; torchsar's AP is pycocotools' with ``useCats = 0``.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from torchsar.objects import Objects
from torchsar_eval.scoring import declared_boxes

__all__ = ["CocoExport", "encode"]


def encode(mask: np.ndarray) -> dict:
    """COCO run-length encoding of a 2-D bool mask (JSON-ready)."""
    # pycocotools only when a mask is encoded (a worker without --export-coco never loads it)
    from pycocotools import mask as mask_utils

    rle = mask_utils.encode(np.asfortranarray(mask.astype(np.uint8)))
    rle["counts"] = rle["counts"].decode("ascii")
    return rle


def _xywh(box) -> list[float]:
    r0, c0, r1, c1 = (float(v) for v in box)
    return [c0, r0, c1 - c0, r1 - r0]


class CocoExport:
    """Collects one dataset's ground truth and every detector's objects batch by batch."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.images: list[dict] = []
        self.annotations: list[dict] = []
        self.categories: dict[str, int] = {}
        self.results: dict[str, list[dict]] = {}

    def _category(self, name: str) -> int:
        return self.categories.setdefault(name, len(self.categories) + 1)

    def _add_truth(self, batch: dict) -> list[int]:
        b, c, h, w = batch["instances"].shape
        inst = batch["instances"].reshape(b * c, h, w).cpu().numpy()
        ignore = batch["ignore"].reshape(b * c, h, w).cpu().numpy()
        ids = []
        for p in range(b * c):
            meta = batch["meta"][p // c]
            index = meta.get("index")
            image_id = len(self.images) + 1 if index is None else int(index) * c + p % c + 1
            ids.append(image_id)
            self.images.append(
                {
                    "id": image_id,
                    "file_name": str(meta.get("name", image_id)),
                    "height": h,
                    "width": w,
                }
            )
            classes = list(meta.get("classes") or [])
            boxes = list(meta.get("boxes") or []) if declared_boxes(meta) else []
            areas = list(meta.get("areas") or [])
            seen = []
            for k in np.unique(inst[p][inst[p] > 0]).tolist():
                m = inst[p] == k
                rows, cols = np.flatnonzero(m.any(1)), np.flatnonzero(m.any(0))
                box = (
                    boxes[k - 1]
                    if k - 1 < len(boxes)
                    else (rows[0], cols[0], rows[-1] + 1, cols[-1] + 1)
                )
                cls = str(classes[k - 1]) if k - 1 < len(classes) else "target"
                area = areas[k - 1] if k - 1 < len(areas) and areas[k - 1] is not None else None
                seen.append(self._category(cls))
                self._annotation(image_id, seen[-1], m, box, crowd=0, area=area)
            if ignore[p].any():
                self._crowd(image_id, ignore[p] & (inst[p] == 0), seen)
        return ids

    def _crowd(self, image_id: int, m: np.ndarray, seen: list[int]) -> None:
        """The ignore pixels as one crowd annotation per category of the image (and the
        first category, that of class-agnostic detections): don't-care for every class."""
        rows, cols = np.flatnonzero(m.any(1)), np.flatnonzero(m.any(0))
        if not rows.size:
            return
        box = (rows[0], cols[0], rows[-1] + 1, cols[-1] + 1)
        first = self._category(next(iter(self.categories), "target"))
        for cat in sorted({first, *seen}):
            self._annotation(image_id, cat, m, box, crowd=1)

    def _annotation(
        self, image_id: int, cat: int, m: np.ndarray, box, *, crowd: int, area: float | None = None
    ) -> None:
        self.annotations.append(
            {
                "id": len(self.annotations) + 1,
                "image_id": image_id,
                "category_id": cat,
                "segmentation": encode(m),
                "area": float(m.sum() if area is None else area),
                "bbox": _xywh(box),
                "iscrowd": crowd,
            }
        )

    def add(self, batch: dict, found: dict[str, Objects]) -> None:
        """Add a batch's ground truth and each detector's objects."""
        ids = self._add_truth(batch)
        for det, obj in found.items():
            out = self.results.setdefault(det, [])
            for k in range(len(obj)):
                out.append(self._result(obj, k, ids[int(obj.plane[k])]))

    def _result(self, obj: Objects, k: int, image_id: int) -> dict:
        cls = obj.classes[k] if obj.classes is not None else None
        rec = {
            "image_id": image_id,
            "category_id": None if cls is None else self._category(cls),
            "bbox": _xywh(obj.box[k]),
            "score": float(obj.score[k]),
        }
        if obj.has_masks:
            rec["segmentation"] = encode(obj.mask_of(k))
            rec["area"] = float(obj.area[k])
        elif obj.geometry == "point":
            rec["point"] = [float(obj.centroid[k, 1]), float(obj.centroid[k, 0])]
        return rec

    @classmethod
    def merge(cls, name: str, parts: Iterable[CocoExport]) -> CocoExport:
        """One export from the exports of consecutive parts of a dataset (shards, in order):
        image, annotation and category ids renumbered as one pass over the whole would."""
        out = cls(name)
        for part in parts:
            anns = len(out.annotations)
            cats = {i: out._category(n) for n, i in part.categories.items()}
            cats[None] = None  # class-agnostic: the first category once written
            out.images += part.images
            out.annotations += [
                {**a, "id": a["id"] + anns, "category_id": cats[a["category_id"]]}
                for a in part.annotations
            ]
            for det, res in part.results.items():
                out.results.setdefault(det, []).extend(
                    {**r, "category_id": cats[r["category_id"]]} for r in res
                )
        return out

    def write(self, folder: Path, stem: str) -> list[Path]:
        """Write ``<stem>__gt.json`` and ``<stem>__<detector>.json`` into ``folder``."""
        folder.mkdir(parents=True, exist_ok=True)
        self._category("target")
        gt = {
            "images": self.images,
            "annotations": self.annotations,
            "categories": [{"id": i, "name": n} for n, i in self.categories.items()],
        }
        paths = [folder / f"{stem}__gt.json"]
        paths[0].write_text(json.dumps(gt))
        for det, res in self.results.items():
            paths.append(folder / f"{stem}__{det}.json")
            rows = [r if r["category_id"] is not None else {**r, "category_id": 1} for r in res]
            paths[-1].write_text(json.dumps(rows))
        return paths
