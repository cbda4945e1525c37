"""Fuzzing the folder reader: every case is a valid item or an EvalError naming the file,
never another exception, never a silently changed label."""

from __future__ import annotations

import tempfile
import warnings
from pathlib import Path

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from tests.eval.datasets_helpers import check_contract
from tests.io.writers import write_png, write_tiff
from torchsar_eval.datasets import make_dataset
from torchsar_eval.errors import EvalError

IMAGE_KINDS = ("png8", "png16", "jpeg", "tif_float", "tif_u16", "rgb_equal", "rgb_colour", "rgba")
MASK_KINDS = ("grey", "rgb_equal", "red_only", "palette", "rgba_equal")


@st.composite
def cases(draw):
    h, w = draw(st.integers(1, 12)), draw(st.integers(1, 12))
    return {
        "shape": (h, w),
        "mask_shape": draw(st.sampled_from([(h, w), (h, w), (h + 1, w), (h, max(1, w - 1))])),
        "image": draw(st.sampled_from(IMAGE_KINDS)),
        "mask": draw(st.sampled_from(MASK_KINDS)),
        "labels": draw(st.lists(st.sampled_from([0, 0, 1, 2, 3, 255]), min_size=1, max_size=4)),
        "truncate": draw(st.sampled_from([None, None, "image", "mask"])),
        "cut": draw(st.floats(0.05, 0.95)),
        "seed": draw(st.integers(0, 2**16)),
    }


def _image(kind: str, shape, rng) -> tuple[str, np.ndarray]:
    grey = rng.integers(0, 256, shape).astype(np.uint8)
    return {
        "png8": ("png", grey),
        "png16": ("png", rng.integers(0, 65536, shape).astype(np.uint16)),
        "jpeg": ("jpeg", grey),
        "tif_float": ("tif", rng.random(shape).astype(np.float32)),
        "tif_u16": ("tif", rng.integers(0, 65536, shape).astype(np.uint16)),
        "rgb_equal": ("png", np.dstack([grey] * 3)),
        "rgb_colour": ("png", rng.integers(0, 256, (*shape, 3)).astype(np.uint8)),
        "rgba": ("png", np.dstack([grey] * 3 + [np.full(shape, 255, np.uint8)])),
    }[kind]


def _mask(kind: str, labels: np.ndarray) -> np.ndarray:
    lab = labels.astype(np.uint8)
    return {
        "grey": lab,
        "rgb_equal": np.dstack([lab] * 3),
        "red_only": np.dstack([lab, lab * 0, lab * 0]),
        "palette": lab,
        "rgba_equal": np.dstack([lab] * 3 + [np.full(lab.shape, 255, np.uint8)]),
    }[kind]


def _write(root: Path, case: dict, rng) -> tuple[Path, Path, np.ndarray]:
    ext, img = _image(case["image"], case["shape"], rng)
    labels = rng.choice(case["labels"], size=case["mask_shape"]).astype(np.uint8)
    img_path, mask_path = root / f"x.{ext}", root / "x.mask.png"
    (write_tiff if ext == "tif" else write_png)(img_path, img)
    write_png(mask_path, _mask(case["mask"], labels), palette=case["mask"] == "palette")
    if case["truncate"]:
        victim = img_path if case["truncate"] == "image" else mask_path
        data = victim.read_bytes()
        victim.write_bytes(data[: int(len(data) * case["cut"])])
    return img_path, mask_path, labels


@given(cases())
def test_folder_reader_never_crashes_nor_changes_labels(case):
    rng = np.random.default_rng(case["seed"])
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        img_path, mask_path, labels = _write(root, case, rng)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                ds = make_dataset(f"folder:{root}")
                item = ds[0]
        except EvalError as exc:
            assert img_path.name in str(exc) or mask_path.name in str(exc), str(exc)
            return
    check_contract(item)
    # a valid item means a valid label map, decoded exactly
    assert case["mask_shape"] == case["shape"]
    assert case["mask"] != "red_only" or not labels.any()
    assert set(np.unique(labels).tolist()) <= {0, 1, 2}
    np.testing.assert_array_equal(item["mask"][0].numpy(), labels == 1)
    np.testing.assert_array_equal(item["ignore"][0].numpy(), labels == 2)
