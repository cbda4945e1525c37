"""A tiny COCO set written by hand: polygon, uncompressed RLE, compressed RLE, crowd, box."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

H, W = 8, 10


def rle_counts(mask: np.ndarray) -> list[int]:
    """Uncompressed COCO RLE by hand: run lengths over the column-major pixels, zeros first."""
    flat = mask.T.ravel().astype(np.int8)
    edges = np.flatnonzero(np.diff(flat)) + 1
    runs = np.diff(np.concatenate([[0], edges, [flat.size]])).tolist()
    return [0, *runs] if flat.size and flat[0] else runs


def truth() -> dict[str, np.ndarray]:
    """The hand-made masks of the set's objects."""
    poly = np.zeros((H, W), bool)
    poly[1:4, 2:6] = True  # polygon corners on pixel boundaries
    rle = np.zeros((H, W), bool)
    rle[5:7, 1:3] = True
    rle[6, 3] = True
    crle = np.zeros((H, W), bool)
    crle[4:6, 7:9] = True
    crowd = np.zeros((H, W), bool)
    crowd[0:2, 8:10] = True
    box = np.zeros((H, W), bool)
    box[7:8, 5:8] = True
    return {"poly": poly, "rle": rle, "crle": crle, "crowd": crowd, "box": box}


def write_coco(folder: Path, image_name: str = "a.png", **overrides) -> Path:
    """Write ``ann.json`` for one ``H x W`` image; ``overrides`` patch top-level keys."""
    from pycocotools import mask as mask_utils

    t = truth()
    compressed = mask_utils.encode(np.asfortranarray(t["crle"].astype(np.uint8)))
    compressed["counts"] = compressed["counts"].decode()

    def bbox(m):
        rr, cc = np.nonzero(m)
        return [
            int(cc.min()),
            int(rr.min()),
            int(cc.max() - cc.min() + 1),
            int(rr.max() - rr.min() + 1),
        ]

    anns = [
        {
            "id": 1,
            "category_id": 1,
            "bbox": bbox(t["poly"]),
            "segmentation": [[2, 1, 6, 1, 6, 4, 2, 4]],
        },
        {
            "id": 2,
            "category_id": 2,
            "bbox": bbox(t["rle"]),
            "segmentation": {"size": [H, W], "counts": rle_counts(t["rle"])},
        },
        {"id": 3, "category_id": 1, "bbox": bbox(t["crle"]), "segmentation": compressed},
        {
            "id": 4,
            "category_id": 1,
            "bbox": bbox(t["crowd"]),
            "iscrowd": 1,
            "segmentation": {"size": [H, W], "counts": rle_counts(t["crowd"])},
        },
        {"id": 5, "category_id": 2, "bbox": bbox(t["box"])},
    ]
    for a in anns:
        a["image_id"] = 7
    data = {
        "images": [{"id": 7, "file_name": image_name, "height": H, "width": W}],
        "annotations": anns,
        "categories": [{"id": 1, "name": "ship"}, {"id": 2, "name": "boat"}],
    }
    data.update(overrides)
    path = folder / "ann.json"
    path.write_text(json.dumps(data))
    return path
