"""COCO annotations: polygons, RLE (both encodings), crowd and boxes against hand-made masks."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.io.coco_fixture import H, W, truth, write_coco
from torchsar.io import FileFormatError, annotation_mask, read_coco


def test_masks_boxes_and_classes(tmp_path):
    coco = read_coco(write_coco(tmp_path))
    (image,) = coco.images
    assert (image.file_name, image.height, image.width) == ("a.png", H, W)
    anns = image.annotations
    t = truth()
    for ann, key in zip(anns, ["poly", "rle", "crle", "crowd", "box"], strict=True):
        np.testing.assert_array_equal(annotation_mask(ann, H, W), t[key], err_msg=key)
    assert [a.category for a in anns] == ["ship", "boat", "ship", "ship", "boat"]
    assert [a.iscrowd for a in anns] == [False, False, False, True, False]
    assert anns[0].box == (1, 2, 4, 6)  # (r0, c0, r1, c1) from bbox [x=2, y=1, w=4, h=3]
    assert anns[4].segmentation is None


def _broken(tmp_path, **patch) -> str:
    path = write_coco(tmp_path)
    data = json.loads(path.read_text())
    for key, fn in patch.items():
        data[key] = fn(data[key])
    path.write_text(json.dumps(data))
    with pytest.raises(FileFormatError) as info:
        read_coco(path)
    assert "ann.json" in str(info.value)
    return str(info.value)


def test_unknown_category(tmp_path):
    msg = _broken(tmp_path, categories=lambda c: c[:1])
    assert "unknown category_id 2" in msg


def test_box_outside_the_image(tmp_path):
    def grow(anns):
        anns[0]["bbox"] = [8, 1, 4, 3]
        return anns

    assert "lies outside image a.png (10x8)" in _broken(tmp_path, annotations=grow)


def test_annotation_of_unknown_image(tmp_path):
    def move(anns):
        anns[1]["image_id"] = 99
        return anns

    assert "unknown image_id 99" in _broken(tmp_path, annotations=move)


def test_not_json(tmp_path):
    path = tmp_path / "x.json"
    path.write_text("{nope")
    with pytest.raises(FileFormatError, match="x.json: is not a readable JSON file"):
        read_coco(path)
