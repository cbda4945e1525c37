"""Operating points without peeking (--calibrate-on) and the run's object outputs."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from torchsar.metrics import ObjectState
from torchsar.metrics.assign import BatchMatch
from torchsar.metrics.matching import ground_truth
from torchsar.metrics.object_state import ImageInfo
from torchsar.objects import Objects
from torchsar_eval.calibrate import Target, choose_threshold, parse_target, split_indices
from torchsar_eval.cli import main
from torchsar_eval.errors import EvalError


def test_split_is_disjoint_deterministic_and_near_the_fraction():
    cal, test = split_indices(1000, "sim-chips", 0.3)
    assert set(cal).isdisjoint(test) and sorted(cal + test) == list(range(1000))
    assert (cal, test) == split_indices(1000, "sim-chips", 0.3)
    assert 250 < len(cal) < 350
    assert split_indices(10, "sim-chips", 0.3)[0] == [i for i in cal if i < 10]  # prefix-stable
    with pytest.raises(EvalError):
        split_indices(10, "x", 1.5)


def test_choose_threshold_by_hand():
    """Two images, two targets; ranked TP 0.9, FP 0.7, FP 0.6, TP 0.2: the threshold is a
    detection score (the highest one left out), never a grid level."""
    score = np.array([0.9, 0.7, 0.6, 0.2])
    obj = Objects.from_points(
        np.zeros((4, 2)), score, shape=(8, 8), plane=np.array([0, 0, 1, 1]), planes=2
    )
    inst = np.zeros((2, 8, 8), int)
    inst[0, 0, 0] = inst[1, 4, 4] = 1
    op = np.array([0, -1, -1, 1])
    m = BatchMatch(
        np.tile(op, (4, 10, 1)),
        op,
        np.zeros(4),
        np.array([0.9, 0.2]),
        np.zeros(2, np.int64),
        np.array([0, 3]),
        "iou",
    )
    st = ObjectState(replicates=0)
    st.update(m, obj, ground_truth(inst), [ImageInfo("a", order=0), ImageInfo("b", order=1)])
    assert choose_threshold(st, Target("fa", 0.0)) == 0.7  # only the top TP
    assert choose_threshold(st, Target("fa", 0.5)) == 0.6  # one false alarm in 2 images
    assert choose_threshold(st, Target("fa", 5.0)) is None  # everything
    # F1: top TP alone 2/3, everything 2*2/(4+2+0) = 2/3: ties go to fewer detections
    assert choose_threshold(st, Target("f1")) == 0.7


def test_parse_target():
    assert parse_target("f1") == Target("f1") and parse_target("fa=0.1") == Target("fa", 0.1)
    for bad in ("fa=-1", "fa=x", "recall=1"):
        with pytest.raises(EvalError, match="calibration target must be"):
            parse_target(bad)


@pytest.mark.figures
def test_run_with_calibration_and_coco_export(tmp_path):
    out = tmp_path / "out"
    argv = [
        "run",
        "--dataset",
        "sim-chips",
        "--n",
        "10",
        "--detectors",
        "ca,region",
        "--calibrate-on",
        "fa=1",
        "--export-coco",
        "--bootstrap",
        "20",
        "--no-progress",
        "--out",
        str(out),
    ]
    assert main(argv) == 0
    s = pd.read_csv(out / "summary.csv")
    test = split_indices(10, "sim-chips", 0.3)[1]
    assert (s["images"] == len(test)).all()
    assert not s["score_threshold"].isna().any()
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["options"]["calibration"] == {"target": "fa=1", "fraction": 0.3}
    assert cfg["options"]["scoring"]["matching"]["kind"] == "centroid"
    gt = json.loads((out / "coco" / "sim-chips__gt.json").read_text())
    assert len(gt["images"]) == len(test)
    dets = json.loads((out / "coco" / "sim-chips__region.json").read_text())
    assert all({"image_id", "bbox", "score", "segmentation"} <= set(d) for d in dets)
    for name in ("breakdown.csv", "per_image.csv", "pr.csv", "roc_sim-chips.pdf"):
        assert (out / name).stat().st_size > 0
    per_image = pd.read_csv(out / "per_image.csv")
    assert len(per_image) == 2 * len(test)


def test_an_unreadable_file_stops_the_run_or_is_skipped_and_counted(tmp_path, capsys):
    from skimage import io

    root = tmp_path / "data"
    root.mkdir()
    for k in range(3):
        img = np.full((32, 32), 20, np.uint8)
        img[10:13, 10:13] = 255
        lab = np.zeros((32, 32), np.uint8)
        lab[10:13, 10:13] = 1
        io.imsave(root / f"c{k}.png", img, check_contrast=False)
        io.imsave(root / f"c{k}.mask.png", lab, check_contrast=False)
    (root / "c1.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"garbage" * 10)
    argv = ["run", "--dataset", f"folder:{root}", "--detectors", "ca", "--no-progress"]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 2
    assert "c1.png" in capsys.readouterr().err and not (tmp_path / "a").exists()
    assert main([*argv, "--out", str(tmp_path / "b"), "--skip-bad"]) == 0
    s = pd.read_csv(tmp_path / "b" / "summary.csv")
    assert s.images.iloc[0] == 2
    assert "skipped 1 unreadable file(s)" in (tmp_path / "b" / "summary.md").read_text()
    cfg = json.loads((tmp_path / "b" / "config.json").read_text())
    assert cfg["options"]["manifests"][f"folder:{root}"]["files"] >= 4


def test_windows_in_metres_are_converted_with_the_pixel_spacing(tmp_path):
    out = tmp_path / "m"
    argv = [
        "run",
        "--dataset",
        "sim-chips",
        "--n",
        "2",
        "--detectors",
        "ca",
        "--window-units",
        "m",
        "--param",
        "ca.guard=0.9",
        "--param",
        "ca.train=1.2",
        "--bootstrap",
        "0",
        "--no-progress",
        "--out",
        str(out),
    ]
    assert main(argv) == 0  # simulated chips: 0.3 m pixels
    cfg = json.loads((out / "config.json").read_text())["options"]
    assert cfg["detectors_in_pixels"]["sim-chips"]["ca"]["guard"] == 3
    assert cfg["detectors_in_pixels"]["sim-chips"]["ca"]["train"] == 4
    bad = [a if a != "ca.train=1.2" else "ca.train=0.1" for a in argv]
    assert main([*bad[:-1], str(tmp_path / "n")]) == 2
