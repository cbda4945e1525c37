"""folder: datasets: formats, declared scaling, spacing, pairing rules, label semantics,
instances, bounded reads, manifest and options."""

from __future__ import annotations

import os
import warnings

import numpy as np
import pytest

import torchsar.io.raster as raster
from tests.eval.datasets_helpers import check_contract, write_pair
from tests.io.writers import write_geotiff, write_png, write_tiff
from torchsar_eval.datasets import BadItemError, DisplayScalingWarning, make_dataset
from torchsar_eval.errors import EvalError

rng = np.random.default_rng(3)


def _labels(shape=(16, 16), boxes=((4, 4, 7, 7),), shadow=None):
    lab = np.zeros(shape, np.uint8)
    for r0, c0, r1, c1 in boxes:
        lab[r0:r1, c0:c1] = 1
    if shadow:
        r0, c0, r1, c1 = shadow
        lab[r0:r1, c0:c1] = 2
    return lab


def _quiet(spec, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return make_dataset(spec, **kw)


@pytest.mark.parametrize(
    ("name", "samples", "query", "sample_type", "expected"),
    [
        ("f.tif", rng.random((16, 16)).astype(np.float32), "", "intensity", lambda a: a),
        (
            "u.tif",
            rng.integers(0, 65535, (16, 16)).astype(np.uint16),
            "",
            "display",
            lambda a: (a / 65535.0) ** 2,
        ),
        (
            "a.tif",
            rng.random((16, 16)).astype(np.float32),
            "?type=amplitude",
            "amplitude",
            lambda a: a.astype(float) ** 2,
        ),
        (
            "d.tif",
            30 * rng.random((16, 16)).astype(np.float32),
            "?type=db",
            "db",
            lambda a: 10 ** (a / 10.0),
        ),
        (
            "c.tif",
            (rng.random((16, 16)) + 1j * rng.random((16, 16))).astype(np.complex64),
            "",
            "complex",
            lambda a: np.abs(a) ** 2,
        ),
        (
            "iq.tif",
            rng.random((16, 16, 2)).astype(np.float32),
            "?type=complex",
            "complex",
            lambda a: a[..., 0].astype(float) ** 2 + a[..., 1].astype(float) ** 2,
        ),
    ],
)
def test_tiff_samples_become_intensity_once(tmp_path, name, samples, query, sample_type, expected):
    write_tiff(tmp_path / name, samples)
    write_png(tmp_path / (name.split(".")[0] + ".mask.png"), _labels())
    ds = _quiet(f"folder:{tmp_path}{query}")
    item = ds[0]
    check_contract(item)
    assert ds.options["sample_type"] == item["meta"]["sample_type"] == sample_type
    np.testing.assert_allclose(item["image"][0].numpy(), expected(samples), rtol=1e-5)


def test_eight_bit_png_is_display_and_warns_once(tmp_path):
    write_pair(tmp_path, "a", np.full((16, 16), 51), _labels())
    write_pair(tmp_path, "b", np.full((16, 16), 102), _labels())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ds = make_dataset(f"folder:{tmp_path}")
        items = [ds[i] for i in range(len(ds))]
    display = [w for w in caught if issubclass(w.category, DisplayScalingWarning)]
    assert len(display) == 1 and "design Pfa is not meaningful" in str(display[0].message)
    np.testing.assert_allclose(items[1]["image"].numpy(), 0.4**2, rtol=1e-6)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DisplayScalingWarning)
        declared = make_dataset(f"folder:{tmp_path}?type=amplitude")
    np.testing.assert_allclose(declared[1]["image"].numpy(), 102.0**2)


def test_spacing_option_and_errors(tmp_path):
    write_pair(tmp_path, "a", np.full((16, 16), 9), _labels())
    assert _quiet(f"folder:{tmp_path}?spacing=0.3")[0]["meta"]["pixel_spacing"] == (0.3, 0.3)
    ds = _quiet(f"folder:{tmp_path}?spacing=0.3,0.5")
    assert ds.options["pixel_spacing"] == ds[0]["meta"]["pixel_spacing"] == (0.3, 0.5)
    assert _quiet(f"folder:{tmp_path}")[0]["meta"]["pixel_spacing"] is None
    for bad in ("0", "x", "1,2,3", "-1"):
        with pytest.raises(EvalError, match="spacing="):
            make_dataset(f"folder:{tmp_path}?spacing={bad}")
    with pytest.raises(EvalError, match=r"unknown folder option\(s\) \['colour'\]"):
        make_dataset(f"folder:{tmp_path}?colour=red")
    with pytest.raises(EvalError, match="option type='linear'"):
        make_dataset(f"folder:{tmp_path}?type=linear")


def test_spacing_sidecar(tmp_path):
    write_pair(tmp_path, "a", np.full((16, 16), 9), _labels())
    write_pair(tmp_path, "b", np.full((16, 16), 9), _labels())
    (tmp_path / "a.spacing.txt").write_text("0.25 0.5\n")
    ds = _quiet(f"folder:{tmp_path}")
    assert [ds[i]["meta"]["pixel_spacing"] for i in range(2)] == [(0.25, 0.5), None]
    assert ds.manifest()["files"] == 5
    assert _quiet(f"folder:{tmp_path}?spacing=1")[0]["meta"]["pixel_spacing"] == (1.0, 1.0)
    (tmp_path / "a.spacing.txt").write_text("fast")
    with pytest.raises(BadItemError, match="a.spacing.txt: spacing="):
        _quiet(f"folder:{tmp_path}")[0]


def test_geotiff_spacing_from_metadata(tmp_path):
    write_geotiff(tmp_path / "g.tif")
    write_png(tmp_path / "g.mask.png", _labels((4, 6), ()))
    ds = _quiet(f"folder:{tmp_path}")
    assert ds[0]["meta"]["pixel_spacing"] == (0.5, 0.75)
    assert _quiet(f"folder:{tmp_path}?spacing=2")[0]["meta"]["pixel_spacing"] == (2.0, 2.0)


def test_mask_without_image_and_shared_mask(tmp_path):
    write_pair(tmp_path, "a", np.zeros((16, 16)), _labels())
    write_png(tmp_path / "b.mask.png", _labels())
    with pytest.raises(EvalError, match=r"mask .*b.mask.png has no image"):
        make_dataset(f"folder:{tmp_path}")
    (tmp_path / "b.mask.png").unlink()
    write_png(tmp_path / "a.jpeg", np.zeros((16, 16), np.uint8))
    with pytest.raises(EvalError, match=r"a.mask.png is shared by 2 images: .*a.jpeg, .*a.png"):
        make_dataset(f"folder:{tmp_path}")


def test_fifo_image_and_mask_are_refused_not_opened(tmp_path):
    write_pair(tmp_path, "a", np.zeros((16, 16)), _labels())
    os.mkfifo(tmp_path / "pipe.png")
    write_png(tmp_path / "pipe.mask.png", _labels())
    with pytest.raises(EvalError, match="pipe.png: is not a regular file"):
        make_dataset(f"folder:{tmp_path}")
    (tmp_path / "pipe.png").unlink()
    (tmp_path / "pipe.mask.png").unlink()
    write_png(tmp_path / "q.png", np.zeros((16, 16), np.uint8))
    os.mkfifo(tmp_path / "q.mask.png")
    with pytest.raises(BadItemError, match="q.mask.png: is not a regular file") as info:
        _quiet(f"folder:{tmp_path}")[1]
    assert info.value.path.endswith("q.mask.png")


def test_label_in_one_channel_is_an_error_not_clutter(tmp_path):
    write_png(tmp_path / "a.png", np.zeros((16, 16), np.uint8))
    lab = _labels()
    write_png(tmp_path / "a.mask.png", np.dstack([lab, lab * 0, lab * 0]))
    with pytest.raises(BadItemError, match="a.mask.png: has 3 channels that differ"):
        _quiet(f"folder:{tmp_path}")[0]


def test_grey_as_rgb_and_palette_masks_keep_their_labels(tmp_path):
    lab = _labels(shadow=(10, 10, 12, 14))
    write_png(tmp_path / "a.png", np.zeros((16, 16), np.uint8))
    write_png(tmp_path / "a.mask.png", np.dstack([lab] * 3))
    write_png(tmp_path / "b.png", np.zeros((16, 16), np.uint8))
    write_png(tmp_path / "b.mask.png", lab, palette=True)
    ds = _quiet(f"folder:{tmp_path}")
    for item in (ds[0], ds[1]):
        np.testing.assert_array_equal(item["mask"][0].numpy(), lab == 1)
        np.testing.assert_array_equal(item["ignore"][0].numpy(), lab == 2)


def test_one_bad_item_does_not_stop_building(tmp_path):
    write_pair(tmp_path, "a", np.zeros((16, 16)), _labels())
    write_pair(tmp_path, "b", np.zeros((16, 16)), _labels() * 3)
    write_pair(tmp_path, "c", np.zeros((16, 16)), _labels())
    ds = _quiet(f"folder:{tmp_path}")
    assert int(ds[0]["mask"].sum()) == int(ds[2]["mask"].sum()) == 9
    with pytest.raises(BadItemError, match="b.mask.png") as info:
        ds[1]
    assert info.value.path.endswith("b.mask.png")


def test_labels_outside_0_1_2_are_named(tmp_path):
    write_pair(tmp_path, "a", np.zeros((16, 16)), _labels() * 3)
    with pytest.raises(BadItemError, match=r"a.mask.png: has labels \[3\]"):
        _quiet(f"folder:{tmp_path}")[0]


def test_pixel_limit_and_huge_mask_refused_before_decoding(tmp_path, monkeypatch):
    write_pair(tmp_path, "a", np.zeros((16, 16)), _labels())
    with pytest.raises(BadItemError, match="a.png: is 16x16 = 256 pixels, over the limit of 255"):
        _quiet(f"folder:{tmp_path}?max_pixels=255")[0]
    write_png(tmp_path / "a.mask.png", np.zeros((1200, 1000), np.uint8))
    monkeypatch.setattr(raster, "_decode", lambda p: pytest.fail(f"decoded {p}"))
    with pytest.raises(BadItemError, match=r"a.mask.png: is 1000x1200 but image .*a.png is 16x16"):
        _quiet(f"folder:{tmp_path}")[0]


@pytest.mark.parametrize(
    ("shadow", "target_px", "ignore_px"), [("ignore", 9, 8), ("clutter", 9, 0), ("target", 17, 0)]
)
def test_shadow_option(tmp_path, shadow, target_px, ignore_px):
    write_pair(tmp_path, "a", np.zeros((16, 16)), _labels(shadow=(10, 10, 12, 14)))
    ds = _quiet(f"folder:{tmp_path}?shadow={shadow}")
    item = ds[0]
    assert (int(item["mask"].sum()), int(item["ignore"].sum())) == (target_px, ignore_px)
    assert ds.options["shadow"] == shadow


def _two_close_blobs(root, n):
    for k in range(n):
        write_pair(
            root, f"c{k}", np.zeros((32, 32)), _labels((32, 32), ((4, 4, 8, 8), (4, 10, 8, 14)))
        )


def test_instance_modes_and_split_warning(tmp_path):
    _two_close_blobs(tmp_path, 3)
    with pytest.warns(UserWarning, match=r"3 of the first 3 images have several instances"):
        ds = make_dataset(f"folder:{tmp_path}?type=amplitude")
    assert ds.options["instances"] == "components"
    assert int(ds[0]["instances"].max()) == 2
    one = make_dataset(f"folder:{tmp_path}?type=amplitude&instances=one-per-image")
    item = one[0]
    check_contract(item)
    assert int(item["instances"].max()) == 1 and item["meta"]["boxes"] == [(4, 4, 8, 14)]


def test_merged_warning_for_far_pieces(tmp_path):
    write_pair(
        tmp_path, "a", np.zeros((32, 32)), _labels((32, 32), ((1, 1, 4, 4), (26, 26, 30, 30)))
    )
    with pytest.warns(UserWarning, match="instance made of pieces far apart"):
        make_dataset(f"folder:{tmp_path}?type=amplitude&instances=one-per-image")


def test_mstar_layout_defaults_one_per_image_and_folder_class(tmp_path):
    _two_close_blobs(tmp_path / "T72", 2)
    for k in range(2):
        (tmp_path / "T72" / f"c{k}.box.txt").write_text("4 4 8 14\n")
    ds = _quiet(f"folder:{tmp_path}")
    assert ds.options["instances"] == "one-per-image"
    item = ds[1]
    assert item["meta"]["class"] == "T72" and item["meta"]["classes"] == ["T72"]
    assert item["meta"]["name"] == "T72/c1.png"


def test_id_maps_are_used_when_present(tmp_path):
    lab = _labels((16, 16), ((2, 2, 6, 10),))
    write_pair(tmp_path, "a", np.zeros((16, 16)), lab)
    ids = np.zeros((16, 16, 3), np.uint8)
    ids[2:6, 2:6] = (200, 0, 0)
    ids[2:6, 6:10] = (0, 0, 200)  # same grey mean, different colour: two instances
    write_png(tmp_path / "a.instances.png", ids)
    ds = _quiet(f"folder:{tmp_path}")
    assert ds.options["instances"] == "idmap"
    inst = ds[0]["instances"][0].numpy()
    assert int(inst.max()) == 2 and (inst[2:6, 2:6] == 1).all() and (inst[2:6, 6:10] == 2).all()
    ids[2, 2] = 0  # a target pixel without an id would silently vanish: refused
    write_png(tmp_path / "a.instances.png", ids)
    with pytest.raises(BadItemError, match="a.instances.png: gives no instance id to 1 target"):
        ds[0]
    write_pair(tmp_path, "b", np.zeros((16, 16)), lab)  # no id map beside this mask
    with pytest.raises(BadItemError, match=r"b.instances.png: is missing: instances=idmap"):
        _quiet(f"folder:{tmp_path}")[1]


def test_manifest_and_symlinks_leaving_the_folder(tmp_path):
    root = tmp_path / "d"
    write_pair(root, "a", np.zeros((16, 16)), _labels())
    write_pair(root, "z", np.zeros((16, 16)), _labels())
    assert _quiet(f"folder:{root}", n=1).manifest()["files"] == 2  # only the files used
    (root / "z.png").unlink()
    (root / "z.mask.png").unlink()
    m1 = _quiet(f"folder:{root}").manifest()
    sizes = sum(p.stat().st_size for p in root.iterdir())
    assert (m1["files"], m1["bytes"], m1["symlinks_outside"]) == (2, sizes, [])
    assert _quiet(f"folder:{root}").manifest()["sha256"] == m1["sha256"]
    write_pair(tmp_path / "elsewhere", "b", np.zeros((16, 16)), _labels())
    for name in ("b.png", "b.mask.png"):
        (root / name).symlink_to(tmp_path / "elsewhere" / name)
    m2 = _quiet(f"folder:{root}").manifest()
    assert m2["files"] == 4 and m2["sha256"] != m1["sha256"]
    assert m2["symlinks_outside"] == ["b.mask.png", "b.png"]


def test_items_are_independent_of_access_order(tmp_path):
    for k in range(3):
        write_pair(tmp_path, f"x{k}", rng.integers(0, 255, (16, 16)), _labels())
    ds = _quiet(f"folder:{tmp_path}")
    forward = [ds[i]["image"] for i in range(3)]
    backward = [ds[i]["image"] for i in reversed(range(3))][::-1]
    assert all(bool((a == b).all()) for a, b in zip(forward, backward, strict=True))


def test_real_mstar_linear(data_dir):
    ds = _quiet(f"folder:{data_dir / 'mstar_sarbake'}?variant=linear")
    assert len(ds) == 100
    assert (ds.options["sample_type"], ds.options["instances"]) == ("amplitude", "one-per-image")
    item = ds[0]
    check_contract(item)
    assert item["meta"]["class"] == "2S1" and int(item["instances"].max()) == 1
