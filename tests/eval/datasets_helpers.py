"""Shared checks and writers of the dataset tests."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch
from scipy.ndimage import find_objects

from tests.io.coco_fixture import rle_counts
from tests.io.writers import write_png

META_KEYS = {"name", "classes", "boxes", "gt", "class", "pixel_spacing", "sample_type"}


def check_contract(item: dict) -> None:
    """Every item: the documented keys, dtypes, shapes and meta consistency."""
    image, mask, inst, ignore = (item[k] for k in ("image", "mask", "instances", "ignore"))
    assert image.dtype == torch.float32 and image.ndim == 3
    assert mask.dtype == torch.bool and inst.dtype == torch.int32 and ignore.dtype == torch.bool
    assert image.shape == mask.shape == inst.shape == ignore.shape
    assert torch.equal(mask, inst > 0)
    assert bool((image >= 0).all())
    meta = item["meta"]
    assert set(meta) >= META_KEYS, META_KEYS - set(meta)
    k = int(inst.max())
    assert len(meta["classes"]) == len(meta["boxes"]) == k
    assert meta["gt"] in ("mask", "box")
    for i, (r0, c0, r1, c1) in enumerate(meta["boxes"], start=1):
        rr, cc = np.nonzero(inst[0].numpy() == i)
        if rr.size:
            assert r0 <= rr.min() and rr.max() < r1 and c0 <= cc.min() and cc.max() < c1


def write_pair(folder: Path, stem: str, image: np.ndarray, labels: np.ndarray, ext="png") -> None:
    """``<stem>.<ext>`` image and ``<stem>.mask.png`` labels (uint8)."""
    folder.mkdir(parents=True, exist_ok=True)
    write_png(folder / f"{stem}.{ext}", image.astype(np.uint8))
    write_png(folder / f"{stem}.mask.png", labels.astype(np.uint8))


def canonical_instances(item: dict) -> np.ndarray:
    """Instance ids renumbered by first appearance in raster order (order-free comparison)."""
    inst = item["instances"][0].numpy()
    values, first, inverse = np.unique(inst, return_index=True, return_inverse=True)
    rank = np.empty(values.size, np.int64)
    rank[np.argsort(np.where(values == 0, -1, first), kind="stable")] = np.arange(values.size)
    return rank[inverse].reshape(inst.shape)


def coco_from_id_maps(images: list[Path], id_maps: list[np.ndarray], out: Path) -> Path:
    """A COCO file (uncompressed RLE per instance) converted from decoded id maps."""
    anns, recs = [], []
    for k, (img, ids) in enumerate(zip(images, id_maps, strict=True), start=1):
        h, w = ids.shape
        recs.append({"id": k, "file_name": img.name, "height": h, "width": w})
        for i, (rs, cs) in enumerate(find_objects(ids), start=1):
            bbox = [cs.start, rs.start, cs.stop - cs.start, rs.stop - rs.start]
            seg = {"size": [h, w], "counts": rle_counts(ids == i)}
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": k,
                    "category_id": 1,
                    "bbox": bbox,
                    "segmentation": seg,
                }
            )
    data = {"images": recs, "annotations": anns, "categories": [{"id": 1, "name": "ship"}]}
    out.write_text(json.dumps(data))
    return out


def write_hrsid_folder(root: Path) -> Path:
    """Two synthetic chips: touching ships of different colours, and a lone ship."""
    root.mkdir(parents=True, exist_ok=True)
    ids = np.zeros((2, 24, 24, 3), np.uint8)
    ids[0, 2:6, 2:12] = (128, 0, 0)
    ids[0, 6:10, 2:12] = (0, 128, 0)  # touches the first ship
    ids[0, 15:20, 15:18] = (128, 128, 0)
    ids[1, 10:14, 3:20] = (0, 0, 128)
    for k in range(2):
        write_png(root / f"P{k}.png", np.dstack([np.full((24, 24), 30 + k, np.uint8)] * 3))
        write_png(root / f"P{k}_instance_id_RGB.png", ids[k])
        write_png(root / f"P{k}_instance_color_RGB.png", (ids[k].any(2) * 128).astype(np.uint8))
    return root
