"""Valid COCO and VOC inputs written by hand, for the bad-input table and the fuzzers to
break: one or two 32 x 32 grey PNG images with a polygon, an uncompressed RLE, a compressed
RLE, a bare box and a crowd region."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from tests.io.coco_fixture import rle_counts
from tests.io.writers import write_png

SIZE = 32
IMAGES = {7: "a.png", 8: "b.png"}


def _mask(r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
    m = np.zeros((SIZE, SIZE), bool)
    m[r0:r1, c0:c1] = True
    return m


def _compressed(mask: np.ndarray) -> str:
    from pycocotools import mask as mask_utils

    return mask_utils.encode(np.asfortranarray(mask.astype(np.uint8)))["counts"].decode()


def coco_doc(n_images: int = 1) -> dict:
    """A valid COCO file: per image a polygon, an uncompressed RLE, a compressed RLE, a bare
    box and a crowd RLE (annotation ids 1..5 on image 7, 6..10 on image 8)."""
    images, anns = [], []
    for image_id, name in list(IMAGES.items())[:n_images]:
        images.append({"id": image_id, "file_name": name, "height": SIZE, "width": SIZE})
        rle, crle, crowd = _mask(12, 16, 3, 7), _mask(20, 24, 20, 26), _mask(28, 31, 10, 14)
        objs = [
            (1, [2, 1, 8, 5], [[2, 1, 10, 1, 10, 6, 2, 6]], 0),
            (2, [3, 12, 4, 4], {"size": [SIZE, SIZE], "counts": rle_counts(rle)}, 0),
            (1, [20, 20, 6, 4], {"size": [SIZE, SIZE], "counts": _compressed(crle)}, 0),
            (2, [25, 2, 4, 3], None, 0),
            (1, [10, 28, 4, 3], {"size": [SIZE, SIZE], "counts": rle_counts(crowd)}, 1),
        ]
        for cat, bbox, seg, crowd_flag in objs:
            a = {"id": len(anns) + 1, "image_id": image_id, "category_id": cat, "bbox": bbox}
            if seg is not None:
                a["segmentation"] = seg
            if crowd_flag:
                a["iscrowd"] = 1
            anns.append(a)
    categories = [{"id": 1, "name": "ship"}, {"id": 2, "name": "boat"}]
    return {"images": images, "annotations": anns, "categories": categories}


def write_images(folder: Path, names=("a.png",)) -> None:
    """32 x 32 grey PNGs (clutter 20, a bright 3 x 3 spot)."""
    folder.mkdir(parents=True, exist_ok=True)
    img = np.full((SIZE, SIZE), 20, np.uint8)
    img[14:17, 14:17] = 250
    for name in names:
        write_png(folder / name, img)


def write_coco_file(folder: Path, doc: dict | str, names=("a.png",)) -> Path:
    """``folder/ann.json`` (a dict as JSON, a string as it is) and its images."""
    write_images(folder, names)
    path = folder / "ann.json"
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return path


def voc_text(size=(SIZE, SIZE), objects=(("ship", (3, 2, 10, 8), 0),), filename="a.png") -> str:
    """A VOC annotation; ``size`` ``(height, width)`` and box corners may be any text."""
    objs = "".join(
        f"<object><name>{n}</name><difficult>{d}</difficult><bndbox><xmin>{b[0]}</xmin>"
        f"<ymin>{b[1]}</ymin><xmax>{b[2]}</xmax><ymax>{b[3]}</ymax></bndbox></object>"
        for n, b, d in objects
    )
    return (
        f"<annotation><filename>{filename}</filename><size><width>{size[1]}</width>"
        f"<height>{size[0]}</height><depth>1</depth></size>{objs}</annotation>"
    )


def write_voc_folder(root: Path, xml: str, names=("a.png",)) -> Path:
    """``root/Annotations/a.xml`` and the images in ``root/JPEGImages``."""
    (root / "Annotations").mkdir(parents=True, exist_ok=True)
    write_images(root / "JPEGImages", names)
    (root / "Annotations" / "a.xml").write_text(xml)
    return root


def load_everything(spec: str) -> list[dict]:
    """Build the dataset, read every item's ground truth alone (as scoring saved predictions
    does), then every item."""
    from torchsar_eval.datasets import make_dataset

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = make_dataset(spec)
        for i in range(len(ds)):
            ds.truth(i)  # first: it trusts the annotated size, reading no pixel
        return [ds[i] for i in range(len(ds))]
