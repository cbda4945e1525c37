"""A ``gt.json`` and a ``results.json``, no image anywhere: scored from Python and from the
CLI, with overlapping float ground-truth boxes, crowd regions and several categories, equal
to ``pycocotools`` (SAR mode per category, and the COCO-compatible stats), and with the
same tables as when the images are present. A results file with a category id the ground
truth does not list is one clear error."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pandas as pd
import pytest

import torchsar_eval as te
from tests.reference.coco_sets import make_set, pycocotools_eval
from torchsar_eval.cli import main

TABLES = ("summary", "froc", "pr", "breakdown", "per_image", "errors", "paired", "scr", "coco")


def _write(folder, seed=3, n_images=6):
    folder.mkdir(parents=True, exist_ok=True)
    gt, dets = make_set(seed, n_images=n_images, segm=False, crowd=True)
    (folder / "gt.json").write_text(json.dumps(gt))
    (folder / "results.json").write_text(json.dumps(dets))
    return gt, dets


def _evaluate(folder, **kw):
    scoring = te.Scoring(matching=te.Matching(kind="box"), coco_compatible=True, replicates=40)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # display-scaled data: no design Pfa (nothing reads it)
        return te.evaluate(
            {"set": f"coco:{folder / 'gt.json'}"},
            [te.predictions(folder / "results.json", name="cnn")],
            scoring=scoring,
            progress=False,
            **kw,
        )


def _ap(ev, t=None) -> float:
    p = ev.eval["precision"][:, :, :, 0, -1] if t is None else ev.eval["precision"][t, :, :, 0, -1]
    return float(p[p > -1].mean())


def test_json_only_equals_pycocotools(tmp_path):
    gt, dets = _write(tmp_path)
    assert not list(tmp_path.glob("*.png"))
    row = _evaluate(tmp_path).row("set", "cnn")
    big = pycocotools_eval(gt, dets, "bbox", max_dets=(1, 10, 100_000))
    assert row.ap50 == pytest.approx(_ap(big, 0), abs=1e-9)
    assert row.ap50_95 == pytest.approx(_ap(big), abs=1e-9)
    assert row.classes == "per-class"
    coco = pycocotools_eval(gt, dets, "bbox")
    res = _evaluate(tmp_path)
    np.testing.assert_allclose(
        res.coco[te.tables.COCO_STATS].to_numpy()[0], coco.stats, rtol=0, atol=1e-12
    )


def test_the_same_tables_with_and_without_the_images(tmp_path):
    from skimage import io as skio

    gt, _ = _write(tmp_path / "no")
    _write(tmp_path / "yes")
    for im in gt["images"]:
        skio.imsave(
            tmp_path / "yes" / im["file_name"],
            np.zeros((im["height"], im["width"]), np.uint8),
            check_contrast=False,
        )
    a, b = _evaluate(tmp_path / "no"), _evaluate(tmp_path / "yes")
    for name in TABLES:
        pd.testing.assert_frame_equal(getattr(a, name), getattr(b, name), obj=name)


def test_from_the_cli(tmp_path, capsys):
    _write(tmp_path)
    out = tmp_path / "run"
    argv = [
        "run",
        "--dataset",
        f"coco:{tmp_path / 'gt.json'}",
        "--predictions",
        f"cnn={tmp_path / 'results.json'}",
        "--match",
        "box",
        "--bootstrap",
        "20",
        "--no-progress",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    s = pd.read_csv(out / "summary.csv")
    assert s.detector.tolist() == ["cnn"] and s.classes.tolist() == ["per-class"]
    pr = pd.read_csv(out / "pr.csv")
    assert "mean" in set(pr["class"]) and len(set(pr["class"])) > 2  # per class, then the mean
    b = pd.read_csv(out / "breakdown.csv")
    assert {"class:ship", "class:tank"} <= set(b.by + ":" + b.key)
    assert main([*argv[:-1], str(tmp_path / "agnostic"), "--class-agnostic"]) == 0
    s2 = pd.read_csv(tmp_path / "agnostic" / "summary.csv")
    assert s2.classes.tolist() == ["agnostic"]


def test_an_unknown_category_id_is_one_clear_error(tmp_path):
    _, dets = _write(tmp_path)
    dets[0]["category_id"] = 99
    (tmp_path / "results.json").write_text(json.dumps(dets))
    with pytest.raises(
        te.EvalError,
        match=r"entry 0 has category_id 99, which the dataset "
        r"does not list \(its categories: 3 \(ship\), 7 \(tank\), 9 \(car\)\)",
    ):
        _evaluate(tmp_path)


def test_the_pixel_free_path_equals_the_item_path(tmp_path, monkeypatch):
    """Saved boxes on an annotation file are scored without pixels; the item-by-item path
    (images of zeros, planes painted) gives the same tables."""
    import torchsar_eval.shards as shards

    _write(tmp_path, seed=11, n_images=9)
    fast = _evaluate(tmp_path)
    monkeypatch.setattr(shards, "objects_only", lambda job: False)
    slow = _evaluate(tmp_path)
    for name in TABLES:
        pd.testing.assert_frame_equal(getattr(fast, name), getattr(slow, name), obj=name)


@pytest.mark.parametrize("seed", [3, 8, 21])
def test_stacked_truth_equals_the_item_by_item_truth(tmp_path, seed):
    """The ground truth of box annotations stacked from their columns (crowd boxes, empty
    images, two image sizes) equals the one built from each item's targets."""
    from torchsar_eval.datasets import make_dataset
    from torchsar_eval.objects_only import _truth_by_item

    _write(tmp_path, seed=seed, n_images=9)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = make_dataset(f"coco:{tmp_path / 'gt.json'}")
    order = [5, 0, 3, 8, 1, 2, 7, 4, 6]
    fast = ds.truth_batch(order)
    slow, skipped = _truth_by_item(ds, order, skip_bad=False)
    assert fast is not None and not skipped and len(fast) == len(slow) >= 1
    for (shape, items, gt, metas), (shape2, items2, gt2, metas2) in zip(fast, slow, strict=True):
        assert (shape, items, metas) == (shape2, items2, metas2)
        for field in (
            "plane",
            "area",
            "box",
            "classes",
            "has_mask",
            "box_only",
            "centroid",
            "spacing",
            "length_m",
            "declared_area",
        ):
            np.testing.assert_array_equal(getattr(gt, field), getattr(gt2, field), err_msg=field)
        for field in ("plane", "classes", "box", "has_mask"):
            np.testing.assert_array_equal(getattr(gt.crowd, field), getattr(gt2.crowd, field))
        np.testing.assert_array_equal(gt.masks.offsets, gt2.masks.offsets)
        assert gt.known_scr_db is None and gt2.known_scr_db is None
