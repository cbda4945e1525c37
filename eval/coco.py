"""COCO export of a run: ground truth (``instances`` format) and each detector's detections
(results format with scores), so anyone can re-score a run with ``pycocotools``.

Boxes are ``[x, y, width, height]`` in pixels, masks run-length encoded. A plane's ignore
pixels become one ``iscrowd`` annotation. torchsar detectors are class-agnostic: detections
carry the first category, and the matching AP is pycocotools' with ``useCats = 0``.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from torchsar.objects import Objects

__all__ = ["CocoExport", "encode"]


def encode(mask: np.ndarray) -> dict:
    """COCO run-length encoding of a 2-D bool mask (JSON-ready)."""
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
            image_id = len(self.images) + 1
            ids.append(image_id)
            self.images.append({"id": image_id, "file_name": str(meta.get("name", image_id)),
                                "height": h, "width": w})  # fmt: skip
            classes = list(meta.get("classes") or [])
            boxes = list(meta.get("boxes") or []) if meta.get("gt") == "box" else []
            for k in np.unique(inst[p][inst[p] > 0]).tolist():
                m = inst[p] == k
                rows, cols = np.flatnonzero(m.any(1)), np.flatnonzero(m.any(0))
                box = boxes[k - 1] if k - 1 < len(boxes) else (rows[0], cols[0], rows[-1] + 1,
                                                              cols[-1] + 1)  # fmt: skip
                cls = str(classes[k - 1]) if k - 1 < len(classes) else "target"
                self._annotation(image_id, self._category(cls), m, box, crowd=0)
            if ignore[p].any():
                m = ignore[p] & (inst[p] == 0)
                rows, cols = np.flatnonzero(m.any(1)), np.flatnonzero(m.any(0))
                if rows.size:
                    box = (rows[0], cols[0], rows[-1] + 1, cols[-1] + 1)
                    self._annotation(image_id, self._category("target"), m, box, crowd=1)
        return ids

    def _annotation(self, image_id: int, cat: int, m: np.ndarray, box, *, crowd: int) -> None:
        self.annotations.append({
            "id": len(self.annotations) + 1, "image_id": image_id, "category_id": cat,
            "segmentation": encode(m), "area": float(m.sum()), "bbox": _xywh(box),
            "iscrowd": crowd,
        })  # fmt: skip

    def add(self, batch: dict, found: dict[str, Objects]) -> None:
        """Add a batch's ground truth and each detector's objects."""
        ids = self._add_truth(batch)
        for det, obj in found.items():
            out = self.results.setdefault(det, [])
            for k in range(len(obj)):
                p = int(obj.plane[k])
                out.append({
                    "image_id": ids[p], "category_id": 1, "bbox": _xywh(obj.box[k]),
                    "score": float(obj.score[k]), "segmentation": encode(obj.labels[p] == k + 1),
                    "area": float(obj.area[k]),
                })  # fmt: skip

    @classmethod
    def merge(cls, name: str, parts: Iterable[CocoExport]) -> CocoExport:
        """One export from the exports of consecutive parts of a dataset (shards, in order):
        image, annotation and category ids renumbered as one pass over the whole would."""
        out = cls(name)
        for part in parts:
            images, anns = len(out.images), len(out.annotations)
            cats = {i: out._category(n) for n, i in part.categories.items()}
            out.images += [{**im, "id": im["id"] + images} for im in part.images]
            out.annotations += [
                {**a, "id": a["id"] + anns, "image_id": a["image_id"] + images,
                 "category_id": cats[a["category_id"]]}
                for a in part.annotations
            ]  # fmt: skip
            for det, res in part.results.items():
                out.results.setdefault(det, []).extend(
                    {**r, "image_id": r["image_id"] + images} for r in res
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
            paths[-1].write_text(json.dumps(res))
        return paths
