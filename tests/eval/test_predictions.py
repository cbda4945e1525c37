"""Saved predictions scored like any detector: COCO results (bbox, segm), point CSV and mask
folders; AP and the COCO-compatible stats against pycocotools on the same files; the round
trip from ``--export-coco``; one-line errors."""

from __future__ import annotations

import contextlib
import io
import json
import warnings

import numpy as np
import pandas as pd
import pytest
import torch
from skimage import io as skio

import torchsar_eval as te
from torchsar.cfar.design import threshold
from torchsar_eval.cli import main
from torchsar_eval.errors import EvalError

SIZE = 96
CATEGORIES = [{"id": 3, "name": "ship"}, {"id": 7, "name": "boat"}]


def _rle(mask: np.ndarray) -> dict:
    from pycocotools import mask as mask_utils

    rle = mask_utils.encode(np.asfortranarray(mask.astype(np.uint8)))
    rle["counts"] = rle["counts"].decode()
    return rle


def _xywh(mask: np.ndarray) -> list[float]:
    rr, cc = np.nonzero(mask)
    return [
        float(cc.min()),
        float(rr.min()),
        float(cc.max() - cc.min() + 1),
        float(rr.max() - rr.min() + 1),
    ]


def write_coco_set(root, seed: int = 0, n_img: int = 5, crowd: bool = False):
    """Images, a COCO ground truth (two categories, non-overlapping masks, areas as the
    mask areas, image ids out of order) and random detections with continuous scores. With
    ``crowd``, one category and crowd regions (torchsar's ignore regions are don't-care for
    every category, pycocotools' crowd for its own: the same with one category)."""
    rng = np.random.default_rng(seed)
    cats = [3] if crowd else [3, 7]
    root.mkdir(parents=True, exist_ok=True)
    images, anns, results = [], [], []
    for k in range(n_img):
        image_id = 100 - 10 * k  # pycocotools sorts ids: the dataset must too
        name = f"im{k}.png"
        skio.imsave(
            root / name, rng.integers(0, 255, (SIZE, SIZE)).astype(np.uint8), check_contrast=False
        )
        images.append({"id": image_id, "file_name": name, "height": SIZE, "width": SIZE})
        taken = np.zeros((SIZE, SIZE), bool)
        for _ in range(int(rng.integers(1, 6))):
            r, c = rng.integers(0, SIZE - 40, 2)
            h, w = rng.integers(4, 40, 2)  # areas across COCO's 32^2 bound
            m = np.zeros((SIZE, SIZE), bool)
            m[r : r + h, c : c + w] = True
            if (m & taken).any():
                continue
            taken |= m
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": image_id,
                    "category_id": int(rng.choice(cats)),
                    "segmentation": _rle(m),
                    "area": float(m.sum()),
                    "bbox": _xywh(m),
                    "iscrowd": 0,
                }
            )
        if crowd and k % 2:
            m = np.zeros((SIZE, SIZE), bool)
            m[SIZE - 12 :, SIZE - 12 :] = True
            m &= ~taken
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": image_id,
                    "category_id": 3,
                    "segmentation": _rle(m),
                    "area": float(m.sum()),
                    "bbox": _xywh(m),
                    "iscrowd": 1,
                }
            )
        if k == 0:
            continue  # an image without predictions
        for _ in range(int(rng.integers(5, 40))):
            r, c = rng.uniform(0, SIZE - 30, 2)
            h, w = rng.uniform(3, 30, 2)
            m = np.zeros((SIZE, SIZE), bool)
            m[int(r) : int(r + h) + 1, int(c) : int(c + w) + 1] = True
            results.append(
                {
                    "image_id": image_id,
                    "category_id": int(rng.choice(cats)),
                    "bbox": [c, r, w, h],
                    "segmentation": _rle(m),
                    "score": float(rng.random()),
                }
            )
    gt = {"images": images, "annotations": anns, "categories": CATEGORIES}
    (root / "gt.json").write_text(json.dumps(gt))
    (root / "dets.json").write_text(json.dumps(results))
    return root / "gt.json", root / "dets.json"


def _cocoeval(gt_path, results, iou_type, use_cats=True, sar=False):
    """pycocotools' evaluation; ``sar``: no detection cap (torchsar's SAR mode)."""
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    with contextlib.redirect_stdout(io.StringIO()):
        gt = COCO(str(gt_path))
        ev = COCOeval(gt, gt.loadRes(results), iou_type)
        ev.params.useCats = int(use_cats)
        if sar:
            ev.params.maxDets = [1, 10, 100_000]
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    return ev


def _sar_ap(ev) -> tuple[float, float]:
    """AP50 and AP50:95 at area ``all`` and the last cap: the mean over categories (and
    thresholds) of the entries pycocotools defines."""
    prec = ev.eval["precision"][:, :, :, 0, -1]  # (T, R, K)

    def ap(p):
        return float(p[p > -1].mean()) if (p > -1).any() else float("nan")

    return ap(prec[0]), ap(prec)


@pytest.mark.parametrize("iou_type", ["bbox", "segm"])
@pytest.mark.parametrize("seed", [0, 1])
def test_scored_file_equals_pycocotools_sar_and_coco_modes(tmp_path, iou_type, seed):
    gt_path, dets = write_coco_set(tmp_path / "set", seed=seed, crowd=seed == 1)
    results = json.loads(dets.read_text())
    if iou_type == "bbox":
        results = [{k: v for k, v in r.items() if k != "segmentation"} for r in results]
        (tmp_path / "boxes.json").write_text(json.dumps(results))
        dets = tmp_path / "boxes.json"
    scoring = te.Scoring(
        matching=te.Matching(kind="box" if iou_type == "bbox" else "mask"),
        replicates=0,
        coco_compatible=True,
    )
    res = te.evaluate(
        f"coco:{gt_path}?type=display",
        [te.predictions(dets, name="cnn")],
        scoring=scoring,
        progress=False,
    )
    row = res.row(f"coco:{gt_path}?type=display", "cnn")
    sar = _sar_ap(_cocoeval(gt_path, results, iou_type, sar=True))  # per category
    assert (row.ap50, row.ap50_95) == pytest.approx(sar, abs=1e-9)
    assert row.classes == "per-class"
    coco = _cocoeval(gt_path, results, iou_type)
    assert res.coco.iou_type.tolist() == [iou_type]
    assert res.coco[te.tables.COCO_STATS].to_numpy()[0] == pytest.approx(coco.stats, abs=1e-12)


def test_round_trip_through_export_coco(tmp_path):
    """A built-in detector's exported detections, scored as a file with the operating
    threshold its summary row states, give its summary row (object level; a CFAR's pixel
    metrics come from its statistic, the file's from its objects' masks, the same for the
    region CFAR whose masks are its regions). The scores are written on the detectors' own
    statistic, with their design thresholds beside them."""
    first = tmp_path / "direct"
    argv = ["run", "--dataset", "sim-chips", "--n", "12", "--no-progress", "--bootstrap", "30"]
    assert (
        main(
            [
                *argv,
                "--detectors",
                "ca,region",
                "--floor",
                "0.5",
                "--export-coco",
                "--out",
                str(first),
            ]
        )
        == 0
    )
    a = pd.read_csv(first / "summary.csv").set_index("detector")
    thr = {d: float(a.loc[d, "score_threshold"]) for d in ("ca", "region")}
    assert thr["ca"] == pytest.approx(threshold("ca", guard=2, train=4, pfa=1e-3), rel=1e-6)
    again = tmp_path / "again"
    assert (
        main(
            [
                *argv,
                "--floor",
                "0.5",
                "--out",
                str(again),
                "--predictions",
                f"ca={first / 'coco' / 'sim-chips__ca.json'}",
                "--predictions",
                f"region={first / 'coco' / 'sim-chips__region.json'}",
                "--param",
                f"ca.threshold={thr['ca']!r}",
                "--param",
                f"region.threshold={thr['region']!r}",
                "--param",
                "ids=position",
            ]
        )
        == 0
    )
    b = pd.read_csv(again / "summary.csv").set_index("detector")
    objects = [c for c in a.columns if c not in ("pd_pixel", "pfa_pixel")]
    pd.testing.assert_frame_equal(a[objects], b[objects])
    pd.testing.assert_series_equal(a.loc["region"], b.loc["region"])
    for table in ("roc.csv", "pr.csv", "per_image.csv"):
        pd.testing.assert_frame_equal(pd.read_csv(first / table), pd.read_csv(again / table))


CENTRES = {"a": [(20, 20), (40, 40)], "b": [(30, 30)]}


class _Targets(torch.utils.data.Dataset):
    """Two 64 x 64 images of anisotropic 0.5 m x 2 m pixels, square targets of known length."""

    name = "targets"

    def __len__(self):
        return 2

    def __getitem__(self, i):
        name = "ab"[i]
        inst = torch.zeros(1, 64, 64, dtype=torch.int32)
        for k, (r, c) in enumerate(CENTRES[name], start=1):
            inst[0, r - 2 : r + 3, c - 2 : c + 3] = k  # centroid (r, c)
        meta = {
            "name": name,
            "pixel_spacing": (0.5, 2.0),
            "gt": "mask",
            "classes": ["ship"] * k,
            "lengths_m": [10.0, 20.0][:k],
        }
        return {
            "image": torch.ones(1, 64, 64),
            "mask": inst > 0,
            "instances": inst,
            "ignore": torch.zeros(1, 64, 64, dtype=torch.bool),
            "meta": meta,
        }


def test_points_csv_with_distance_matching_in_pixels_and_metres(tmp_path):
    """3.5 px off in columns is within 5 px but 7 m away with 2 m columns."""
    rows = [
        {"image": "a", "row": 20, "col": 23.5, "score": 0.9, "length_m": 11.0},
        {"image": "a", "row": 40, "col": 40, "score": 0.8, "length_m": 18.0},
        {"image": "b", "row": 5, "col": 5, "score": 0.7},
    ]
    path = tmp_path / "points.csv"
    pd.DataFrame(rows).to_csv(path, index=False)
    counts = {}
    for units in ("px", "m"):
        rule = te.Matching(kind="distance", max_distance=5.0, distance_units=units)
        res = te.evaluate(
            {"targets": _Targets()},
            [te.predictions(path, threshold=0.5)],
            scoring=te.Scoring(matching=rule, replicates=0),
            progress=False,
        )
        row = res.summary.iloc[0]
        counts[units] = (row.tp, row.fp, row.fn, row.length_score)
        assert pd.isna(row.pd_pixel) and pd.isna(row.mean_iou) and pd.isna(row.ap50_95)
    assert counts["px"] == (2, 1, 1, pytest.approx(0.9))  # errors 0.1 and 0.1
    assert counts["m"] == (1, 2, 2, pytest.approx(0.9))  # only the second: 2 / 20


def test_mask_folder_ids_with_scores_and_score_maps(tmp_path):
    from torchsar_eval.datasets import make_dataset

    sim = make_dataset("sim-chips", n=2)
    ids, maps = tmp_path / "ids", tmp_path / "maps"
    ids.mkdir()
    maps.mkdir()
    for i in range(2):
        inst = sim[i]["instances"][0].numpy().astype(np.int32)
        name = f"{i}"  # the items' stems: sim-chips/0 -> "0"
        np.save(ids / f"{name}.npy", inst)
        (ids / f"{name}.scores.json").write_text(json.dumps({"1": 0.7}))
        np.save(maps / f"{name}.npy", (inst > 0) * 0.9 + 0.05)
    res = te.evaluate(
        "sim-chips",
        [
            te.predictions(ids, name="ids", threshold=0.5),
            te.predictions(maps, name="maps", threshold=0.5),
        ],
        n=2,
        progress=False,
    )
    s = res.summary.set_index("detector")
    assert (s.loc["ids", ["tp", "fp", "fn"]] == [2, 0, 0]).all()
    assert s.loc["ids", "ap50"] == 1.0 and s.loc["ids", "pd_pixel"] == 1.0
    assert (s.loc["maps", ["tp", "fp", "fn"]] == [2, 0, 0]).all()


def test_mask_folder_huge_ids_two_files_and_lying_headers(tmp_path):
    """An instance id of 2**31 - 1 is relabelled (on the code before: a 16 GiB table); two
    files for one image are refused (before: one won silently); a .npy whose header
    declares a huge array is refused before it is read."""
    from torchsar_eval.datasets import make_dataset
    from torchsar_eval.errors import EvalError

    sim = make_dataset("sim-chips", n=2)
    folder = tmp_path / "ids"
    folder.mkdir()
    for i in range(2):
        inst = sim[i]["instances"][0].numpy().astype(np.int64)
        np.save(folder / f"{i}.npy", np.where(inst > 0, 2**31 - 1 - inst, 0))
        (folder / f"{i}.scores.json").write_text(json.dumps({str(2**31 - 2): 0.7}))
    res = te.evaluate(
        "sim-chips", [te.predictions(folder, name="ids", threshold=0.5)], n=2, progress=False
    )
    assert res.summary[["tp", "fp", "fn"]].iloc[0].tolist() == [2, 0, 0]
    np.save(folder / "0b.npy", np.zeros((4, 4)))
    (folder / "0b.npy").rename(folder / "0.png")
    with pytest.raises(EvalError, match="both the mask of image 0"):
        te.predictions(folder)
    (folder / "0.png").unlink()
    header = np.lib.format.header_data_from_array_1_0(np.zeros((2, 2), np.int32))
    header["shape"] = (100_000, 100_000)
    with open(folder / "1.npy", "wb") as f:
        np.lib.format.write_array_header_1_0(f, header)
        f.write(np.zeros(4, np.int32).tobytes())
    with pytest.raises(EvalError):
        te.evaluate(
            "sim-chips", [te.predictions(folder, name="ids", threshold=0.5)], n=2, progress=False
        )


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{}", "is not a COCO results list"),
        ('{"images": [], "annotations": []}', "is a COCO ground-truth file"),
        ('[{"image_id": 1, "bbox": [0, 0, 2, 2]}]', "entry 0 score must be a number"),
        ('[{"image_id": 1, "bbox": [0, 0, -2, 2], "score": 1}]', "negative or infinite side"),
        ('[{"bbox": [0, 0, 2, 2], "score": 1}]', "entry 0 has no image_id"),
        ('[{"image_id": 99, "bbox": [0, 0, 2, 2], "score": 1}]', "the dataset has no image ids"),
        (
            '[{"file_name": "nope.png", "bbox": [0, 0, 2, 2], "score": 1}]',
            "1 image(s) not in the dataset",
        ),
        ("[{", "is not a readable JSON file"),
        ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
        (
            '[{"image_id": 1, "bbox": [0, 0, 2, 2], "score": ' + "9" * 5000 + "}]",
            "is not a readable JSON file",
        ),
        ('[{"image_id": "1", "bbox": [0, 0, 2, 2], "score": 1}]', "is not an integer id"),
    ],
)
def test_bad_results_files_are_one_line(tmp_path, capsys, content, message):
    path = tmp_path / "dets.json"
    path.write_text(content)
    code = main(
        [
            "run",
            "--dataset",
            "sim-chips",
            "--n",
            "2",
            "--predictions",
            f"x={path}",
            "--no-progress",
            "--out",
            str(tmp_path / "out"),
        ]
    )
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and message in lines[0], lines
    assert not (tmp_path / "out").exists()


def test_predictions_need_one_dataset_and_known_options(tmp_path, capsys):
    path = tmp_path / "dets.json"
    path.write_text("[]")
    assert main(["run", "--predictions", f"x={path}", "--no-progress"]) == 2
    assert "--predictions scores one dataset" in capsys.readouterr().err
    assert (
        main(
            [
                "run",
                "--dataset",
                "sim-chips",
                "--predictions",
                f"x={path}",
                "--param",
                "x.guard=3",
                "--no-progress",
            ]
        )
        == 2
    )
    assert "saved predictions take only" in capsys.readouterr().err
    with pytest.raises(EvalError, match="do not exist"):
        te.predictions(tmp_path / "missing.json")


def test_one_id_rule_for_every_format(tmp_path):
    """An integer id (COCO ``image_id``, a CSV ``image_id`` column) is the image's COCO id
    or, declared with ids='position', its 1-based position in every format (undeclared on a
    dataset without ids: refused); a name is a name and never taken for a position (on the
    code before, CSV ``image_id=1`` scored against the second sim-chips image)."""
    import json

    import torchsar_eval as te
    from torchsar_eval.errors import EvalError

    ds = "sim-chips"
    te.evaluate(ds, ["ca"], n=4, export_coco=True, out=tmp_path / "ref", progress=False)
    saved = tmp_path / "ref" / "coco" / "sim-chips__ca.json"
    dets = json.loads(saved.read_text())
    (tmp_path / "p.csv").write_text(
        "image_id,row,col,score\n"
        + "".join(
            f"{d['image_id']},{d['bbox'][1] + d['bbox'][3] / 2 - 0.5},"
            f"{d['bbox'][0] + d['bbox'][2] / 2 - 0.5},{d['score']}\n"
            for d in dets
        )
    )
    scoring = te.Scoring(matching=te.Matching(kind="distance", max_distance=3))
    with pytest.raises(EvalError, match="has no image ids.*ids='position'"):
        te.evaluate(ds, [te.predictions(saved, name="p")], n=4, progress=False)
    json_res = te.evaluate(
        ds,
        [te.predictions(saved, name="p", iou_type="bbox", ids="position")],
        n=4,
        scoring=scoring,
        progress=False,
    )
    csv_res = te.evaluate(
        ds,
        [te.predictions(tmp_path / "p.csv", name="p", ids="position")],
        n=4,
        scoring=scoring,
        progress=False,
    )
    per_image = {d["image_id"] for d in dets}
    assert len(per_image) >= 2  # several images: a shifted id would show
    assert json_res.per_image.objects.tolist() == csv_res.per_image.objects.tolist()
    assert json_res.per_image.tp.tolist() == csv_res.per_image.tp.tolist()
    # a digit string in a name column is a name: refused when no image has it
    (tmp_path / "n.csv").write_text("image,row,col\n99,5,5\n")
    with pytest.raises(EvalError, match="given as a name"):
        te.evaluate(ds, [te.predictions(tmp_path / "n.csv", name="p")], n=4, progress=False)
    (tmp_path / "bad.csv").write_text("image_id,row,col\nchip.png,5,5\n")
    with pytest.raises(EvalError, match="not an integer id"):
        te.predictions(tmp_path / "bad.csv")
    (tmp_path / "big.csv").write_text("image_id,row,col\n" + "4" * 400 + ",5,5\n")
    with pytest.raises(EvalError, match="not an integer id"):
        te.predictions(tmp_path / "big.csv")
    for column in ("row", "score"):  # (before: OverflowError tracebacks)
        values = {"row": "5", "col": "5", "score": "1"}
        values[column] = "4" * 400
        (tmp_path / "big.csv").write_text(
            "image,row,col,score\n0,{row},{col},{score}\n".format(**values)
        )
        with pytest.raises(EvalError, match=f"{column} '4444.*' is not a finite number"):
            te.predictions(tmp_path / "big.csv")


def test_a_huge_finite_box_is_one_false_alarm(tmp_path):
    """``[0, 0, 1e300, 1e300]`` (finite, far past the image): one false alarm of no size bin
    a target has, no overflow (before: area -2**63 in the small bin)."""
    gt = {
        "images": [{"id": 1, "file_name": "a.png", "height": 64, "width": 64}],
        "categories": [{"id": 1, "name": "ship"}],
        "annotations": [
            {
                "id": 1,
                "image_id": 1,
                "category_id": 1,
                "bbox": [10, 10, 20, 8],
                "area": 160,
                "iscrowd": 0,
            }
        ],
    }
    (tmp_path / "gt.json").write_text(json.dumps(gt))
    (tmp_path / "r.json").write_text(
        json.dumps(
            [
                {"image_id": 1, "category_id": 1, "bbox": [0, 0, 1e300, 1e300], "score": 0.9},
                {"image_id": 1, "category_id": 1, "bbox": [10, 10, 20, 8], "score": 0.5},
            ]
        )
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        warnings.simplefilter("error", RuntimeWarning)  # no overflow anywhere
        res = te.evaluate(
            f"coco:{tmp_path / 'gt.json'}",
            [te.predictions(tmp_path / "r.json", name="cnn")],
            scoring=te.Scoring(matching=te.Matching(kind="box")),
            progress=False,
        )
    row = res.summary.iloc[0]
    assert (row.tp, row.fp) == (1, 1)
    sizes = res.breakdown[res.breakdown.by == "size"]
    assert set(sizes.key) <= {"small", "medium", "large"} and (sizes.fp >= 0).all()


@pytest.mark.parametrize("length", ["-5", "inf"])
def test_a_points_length_that_is_not_a_length_is_refused(tmp_path, length):
    """(found by the fuzzer: a negative length reached the length metric and crashed)"""
    from torchsar_eval.errors import EvalError

    (tmp_path / "p.csv").write_text(f"image_id,row,col,length_m\n1,5,5,{length}\n")
    with pytest.raises(EvalError, match="is not a length in metres"):
        te.predictions(tmp_path / "p.csv")


def test_saved_predictions_report_no_detection_time(tmp_path):
    """Reading a file is not a detector's speed: saved predictions have no ms_per_image (so
    they are never the fastest row), a detector beside them has its own."""

    import torchsar_eval as te

    res0 = te.evaluate("sim-chips", ["ca"], n=3, progress=False, scoring=te.Scoring(replicates=0))
    assert res0.timing.ms_per_image.notna().all()
    path = tmp_path / "p.csv"
    rows = res0.per_image  # one point per image: the chip's centre
    path.write_text("image,row,col,score\n" + "".join(f"{im},16,16,0.5\n" for im in rows.image))
    res = te.evaluate(
        "sim-chips",
        ["ca", te.predictions(path, name="saved")],
        n=3,
        progress=False,
        scoring=te.Scoring(replicates=0),
    )
    t = res.timing.set_index("detector")
    assert np.isnan(t.loc["saved", "ms_per_image"]) and t.loc["ca", "ms_per_image"] > 0
    assert t.loc["saved", "images_per_s"] > 0
