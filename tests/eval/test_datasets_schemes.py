"""coco:, voc:, hrsid:, phoenix: and the simulated datasets against hand-made truth."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import torch

import torchsar as ts
from tests.eval.datasets_helpers import (
    canonical_instances,
    check_contract,
    coco_from_id_maps,
    write_hrsid_folder,
)
from tests.io.coco_fixture import H, W, truth, write_coco
from tests.io.writers import voc_xml, write_phoenix, write_png
from torchsar.io import decode_id_map, read_raster
from torchsar_eval.datasets import BadItemError, SimDataset, make_dataset
from torchsar_eval.errors import EvalError


def _quiet(spec, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return make_dataset(spec, **kw)


# --- COCO -------------------------------------------------------------------------------


def test_coco_polygon_rle_crowd_and_box(tmp_path):
    write_png(tmp_path / "a.png", np.full((H, W), 7, np.uint8))
    ds = _quiet(f"coco:{write_coco(tmp_path)}?spacing=0.5")
    item = ds[0]
    check_contract(item)
    t = truth()
    inst = item["instances"][0].numpy()
    for i, key in enumerate(["poly", "rle", "crle", "box"], start=1):
        np.testing.assert_array_equal(inst == i, t[key], err_msg=key)
    np.testing.assert_array_equal(item["ignore"][0].numpy(), t["crowd"])
    meta = item["meta"]
    assert meta["classes"] == ["ship", "boat", "ship", "boat"]
    assert meta["boxes"][0] == (1, 2, 4, 6)
    assert meta["gt"] == "box"  # one object has only a box: match by box IoU
    assert (meta["name"], meta["pixel_spacing"], meta["sample_type"]) == (
        "a.png",
        (0.5, 0.5),
        "display",
    )
    assert ds.options["categories"] == ["boat", "ship"]
    assert ds.manifest()["files"] == 2


def test_coco_fully_segmented_image_is_mask_gt(tmp_path):
    write_png(tmp_path / "a.png", np.zeros((H, W), np.uint8))
    path = write_coco(tmp_path)
    data = json.loads(path.read_text())
    data["annotations"] = data["annotations"][:4]
    path.write_text(json.dumps(data))
    assert _quiet(f"coco:{path}")[0]["meta"]["gt"] == "mask"


def test_coco_images_option_and_missing_image(tmp_path):
    """An annotation file scores without its images (saved predictions read none); an item
    whose pixels are read fails naming the missing file."""
    from torchsar_eval.datasets.base import BadItemError

    (tmp_path / "imgs").mkdir()
    path = write_coco(tmp_path)
    ds = _quiet(f"coco:{path}")
    assert ds.options["missing_images"] == 1 and ds.manifest()["files"] == 1  # the JSON
    with pytest.raises(BadItemError, match=r"a.png: does not exist"):
        ds[0]
    t = ds.truth(0)
    assert t["image"].shape[-2:] == (H, W) and len(t["targets"]) == 4
    write_png(tmp_path / "imgs" / "a.png", np.zeros((H, W), np.uint8))
    assert len(_quiet(f"coco:{path}?images={tmp_path / 'imgs'}")) == 1


def test_coco_bad_annotations_are_named(tmp_path):
    write_png(tmp_path / "a.png", np.zeros((H, W), np.uint8))
    path = write_coco(tmp_path, categories=[{"id": 1, "name": "ship"}])
    with pytest.raises(
        EvalError, match=r"ann.json: annotations\[1\] \(id 2\) has unknown category_id 2"
    ):
        make_dataset(f"coco:{path}")
    image = {"id": 7, "file_name": "a.png", "height": H, "width": 20}
    path = write_coco(tmp_path, images=[image], annotations=[])  # (RLE sizes would differ)
    with pytest.raises(BadItemError, match=r"a.png: is 10x8 but its annotation says 20x8"):
        _quiet(f"coco:{path}")[0]


# --- VOC --------------------------------------------------------------------------------


def test_voc_boxes_in_voc_layout(tmp_path):
    (tmp_path / "Annotations").mkdir()
    (tmp_path / "JPEGImages").mkdir()
    write_png(tmp_path / "JPEGImages" / "s1.png", np.zeros((20, 30), np.uint8))
    objects = [("ship", (1, 1, 5, 3), 0), ("boat", (10, 4, 30, 20), 0), ("ship", (20, 2, 22, 3), 1)]
    (tmp_path / "Annotations" / "s1.xml").write_text(voc_xml("s1.png", (20, 30), objects))
    ds = _quiet(f"voc:{tmp_path}")
    item = ds[0]
    check_contract(item)
    meta = item["meta"]
    assert (meta["gt"], meta["classes"]) == ("box", ["ship", "boat"])
    assert meta["boxes"] == [(0, 0, 3, 5), (3, 9, 20, 30)]
    inst = item["instances"][0].numpy()
    expected = np.zeros((20, 30), np.int32)
    expected[0:3, 0:5] = 1
    expected[3:20, 9:30] = 2
    np.testing.assert_array_equal(inst, expected)
    ignore = np.zeros((20, 30), bool)
    ignore[1:3, 19:22] = True  # the difficult object
    np.testing.assert_array_equal(item["ignore"][0].numpy(), ignore)


def test_image_annotated_twice(tmp_path):
    write_png(tmp_path / "s1.png", np.zeros((20, 30), np.uint8))
    for name in ("a.xml", "b.xml"):
        (tmp_path / name).write_text(voc_xml("s1.png", (20, 30), []))
    with pytest.raises(EvalError, match=r"voc annotations describe image .*s1.png more than once"):
        make_dataset(f"voc:{tmp_path}")


@pytest.mark.parametrize("alias", ["./sub/../s1.png", "link.png", "./missing.png"])
def test_coco_image_under_two_names(tmp_path, alias):
    """One image named twice in a COCO file (a path alias, a symbolic link, a missing
    image as ``./x`` and ``x``) would be scored twice: refused, naming both."""
    import json

    write_png(tmp_path / "s1.png", np.zeros((20, 30), np.uint8))
    (tmp_path / "sub").mkdir()
    (tmp_path / "link.png").symlink_to(tmp_path / "s1.png")
    first = "missing.png" if alias == "./missing.png" else "s1.png"
    images = [
        {"id": k + 1, "file_name": n, "height": 20, "width": 30}
        for k, n in enumerate([first, alias])
    ]
    (tmp_path / "gt.json").write_text(
        json.dumps({"images": images, "annotations": [], "categories": [{"id": 1, "name": "ship"}]})
    )
    with pytest.raises(EvalError, match=r"coco annotations describe image .* more than once"):
        make_dataset(f"coco:{tmp_path / 'gt.json'}")


def test_voc_missing_image_and_no_xml(tmp_path):
    from torchsar_eval.datasets.base import BadItemError

    (tmp_path / "x.xml").write_text(voc_xml("gone.jpg", (20, 30), []))
    ds = make_dataset(f"voc:{tmp_path}")  # the annotations alone: saved predictions score
    assert ds.truth(0)["image"].shape[-2:] == (20, 30)
    with pytest.raises(BadItemError, match=r"gone.jpg: does not exist"):
        ds[0]
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(EvalError, match="no VOC"):
        make_dataset(f"voc:{empty}")


# --- HRSID ------------------------------------------------------------------------------


def test_hrsid_colours_become_instances(tmp_path):
    ds = _quiet(f"hrsid:{write_hrsid_folder(tmp_path / 'h')}")
    counts = [int(ds[i]["instances"].max()) for i in range(len(ds))]
    assert counts == [3, 1]
    item = ds[0]
    check_contract(item)
    assert item["meta"]["classes"] == ["ship"] * 3 and item["meta"]["gt"] == "mask"
    assert item["meta"]["boxes"][:2] == [(2, 2, 6, 12), (6, 2, 10, 12)]


def test_hrsid_equals_its_coco_conversion(tmp_path):
    root = write_hrsid_folder(tmp_path / "h")
    _same_as_coco(root, tmp_path)


def _same_as_coco(root, tmp_path):
    """hrsid:ROOT and a COCO file converted from the same id maps give the same instances."""
    hrsid = _quiet(f"hrsid:{root}")
    images = sorted(p for p in root.glob("*.png") if "_instance_" not in p.name)
    id_maps = [
        decode_id_map(read_raster(p.with_name(p.stem + "_instance_id_RGB.png")), "x.png")
        for p in images
    ]
    coco = _quiet(
        f"coco:{coco_from_id_maps(images, id_maps, tmp_path / 'conv.json')}?images={root}"
    )
    assert len(coco) == len(hrsid) == len(images)
    for i in range(len(images)):
        a, b = hrsid[i], coco[i]
        assert a["meta"]["name"] == b["meta"]["name"]
        assert int(a["instances"].max()) == int(b["instances"].max())
        np.testing.assert_array_equal(canonical_instances(a), canonical_instances(b))
        assert torch.equal(a["image"], b["image"])
    return hrsid


def test_real_hrsid_counts(data_dir):
    from skimage.measure import label

    hrsid = _quiet(f"hrsid:{data_dir / 'hrsid'}")
    counts = [int(hrsid[i]["instances"].max()) for i in range(len(hrsid))]
    assert counts == [10, 122, 8, 6]  # one colour per ship
    # the 4-connected components of the ship masks merge touching ships: 9, 114, 7, 6
    components = [int(label(hrsid[i]["mask"][0].numpy(), connectivity=1).max()) for i in range(4)]
    assert components == [9, 114, 7, 6]


@pytest.mark.slow
def test_real_hrsid_equals_its_coco_conversion(data_dir, tmp_path):
    hrsid = _same_as_coco(data_dir / "hrsid", tmp_path)
    assert [int(hrsid[i]["instances"].max()) for i in range(len(hrsid))] == [10, 122, 8, 6]


# --- Phoenix ----------------------------------------------------------------------------


def test_phoenix_folder_spacing_class_and_mask(tmp_path):
    rng = np.random.default_rng(5)
    mag = rng.random((12, 10)).astype(np.float32)
    ph = rng.random((12, 10)).astype(np.float32)
    (tmp_path / "BMP2").mkdir()
    path = write_phoenix(tmp_path / "BMP2" / "HB1.015", mag, ph, spacing=(0.2, 0.25))
    lab = np.zeros((12, 10), np.uint8)
    lab[3:6, 3:5] = 1
    lab[3:6, 6:7] = 1  # a second piece of the same vehicle, 1 px away
    lab[8:10, 3:7] = 2
    write_png(path.with_name(path.name + ".mask.png"), lab)
    write_phoenix(tmp_path / "HB2.016", mag[:4, :4], ph[:4, :4], spacing=None, target="slicey")
    (tmp_path / "readme.txt").write_text("not data")
    ds = _quiet(f"phoenix:{tmp_path}")
    assert len(ds) == 2
    a, b = ds[0], ds[1]
    check_contract(a)
    np.testing.assert_allclose(a["image"][0].numpy(), mag.astype(float) ** 2, rtol=1e-6)
    assert (a["meta"]["class"], a["meta"]["pixel_spacing"], a["meta"]["classes"]) == (
        "BMP2",
        (0.2, 0.25),
        ["BMP2"],
    )
    assert int(a["instances"].max()) == 1 and int(a["ignore"].sum()) == 8
    assert (b["meta"]["class"], b["meta"]["pixel_spacing"], int(b["mask"].sum())) == (
        "slicey",
        None,
        0,
    )
    assert _quiet(f"phoenix:{tmp_path}?spacing=0.3")[1]["meta"]["pixel_spacing"] == (0.3, 0.3)
    cplx = _quiet(f"phoenix:{tmp_path}?type=complex")[0]
    np.testing.assert_allclose(cplx["image"], a["image"], rtol=1e-5)


def test_phoenix_lying_header_is_a_bad_item(tmp_path):
    write_phoenix(
        tmp_path / "HB1.015", np.ones((4, 4), np.float32), np.zeros((4, 4), np.float32), rows=5
    )
    with pytest.raises(BadItemError, match="HB1.015: Phoenix header says 5x4"):
        _quiet(f"phoenix:{tmp_path}")[0]


def test_real_phoenix(data_dir):
    item = _quiet(f"phoenix:{data_dir / 'mstar_raw'}")[0]
    check_contract(item)
    assert item["image"].shape == (1, 54, 54)
    assert item["meta"]["pixel_spacing"] == (0.202148, 0.203125)


# --- simulated --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kind", "make", "options"),
    [
        ("sim-chips", ts.simulate.chips, {"size": 64, "length_px": (10.0, 20.0)}),
        ("sim-scenes", ts.simulate.scenes, {"size": 192}),
    ],
)
def test_sim_items_equal_batch_generation_in_any_order(kind, make, options):
    n = 3
    ds = SimDataset(kind, n, 11, **options)
    batch = make(n, seed=11, **options)
    order = [2, 0, 1]
    items = {i: ds[i] for i in order}
    for i in range(n):
        check_contract(items[i])
        for key in ("image", "mask", "instances", "ignore", "clean"):
            assert torch.equal(items[i][key], batch[i][key]), key
        meta = items[i]["meta"]
        assert meta["pixel_spacing"] == (batch[i]["meta"]["pixel_m"],) * 2
        assert (meta["gt"], meta["class"], meta["sample_type"]) == ("mask", None, "intensity")
        assert meta["name"] == f"{kind}/{i}"
    assert torch.equal(ds[1]["image"], items[1]["image"])  # again, after other items
    with pytest.raises(IndexError):
        ds[n]
    assert len(make_dataset(kind, n=5)) == 5
    with pytest.raises(EvalError, match="n=-1: must be >= 0"):
        make_dataset(kind, n=-1)


def test_store_scheme_reads_a_written_store(tmp_path):
    from torchsar_eval.store import write_store

    src = make_dataset("sim-chips", n=3, seed=2)
    write_store((src[i] for i in range(3)), 3, tmp_path / "s", shard_size=2)
    ds = make_dataset(f"store:{tmp_path / 's'}", n=2)
    assert len(ds) == 2 and torch.equal(ds[1]["image"], src[1]["image"])
    with pytest.raises(EvalError, match=r"unknown store option\(s\) \['x'\]"):
        make_dataset(f"store:{tmp_path / 's'}?x=1")
