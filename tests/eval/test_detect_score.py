"""Planted targets found by ``torchsar-eval detect`` at their pixels, and the detection CSV
scored back by the evaluator against them (``scene:FILE?truth=CSV`` with the distance
rule); the scene dataset's chips and point placement."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from torchsar.simulate.scene_file import write_scene_file
from torchsar_eval.cli import main
from torchsar_eval.datasets import make_dataset
from torchsar_eval.errors import EvalError

DETECTORS = {
    "ca": ["--detector", "ca", "--param", "guard=4", "--param", "train=8", "--param", "pfa=1e-8"],
    "region": ["--detector", "region", "--param", "min_size=1"],
}
TOLERANCE_PX = 0
"""A planted target's peak pixel is the brightest of its extent, and so the pixel of the
highest statistic of its object: reported exactly (0 px) by both detectors."""


pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def planted(tmp_path_factory):
    path = tmp_path_factory.mktemp("planted") / "grd.tif"
    return write_scene_file(path, shape=(1600, 1300), tile=256, n_targets=24, seed=11, pool=4)


def _found(table: pd.DataFrame, targets: pd.DataFrame) -> np.ndarray:
    """Per target, the distance (px) to the nearest reported point."""
    det = table[["detect_scene_row", "detect_scene_column"]].to_numpy(np.float64)
    tgt = targets[["row", "col"]].to_numpy(np.float64)
    d = np.hypot(*(tgt[:, None, :] - det[None, :, :]).transpose(2, 0, 1))
    return d.min(axis=1)


def _score(scene, csv: Path, out: Path, name: str, *argv: str) -> pd.Series:
    dataset = f"scene:{scene.path}?truth={scene.targets_csv}&chip=512"
    args = [
        "run",
        "--dataset",
        dataset,
        "--predictions",
        f"{name}={csv}",
        "--match",
        "distance",
        "--max-distance",
        "1px",
        "--bootstrap",
        "0",
        "--out",
        str(out),
        "--no-progress",
        *argv,
    ]
    assert main(args) == 0
    return pd.read_csv(out / "summary.csv").iloc[0]


@pytest.mark.parametrize("detector", ["ca", "region"])
def test_planted_targets_reported_and_scored_back(planted, tmp_path, detector, capsys):
    out = tmp_path / detector
    argv = [
        "detect",
        "--scene",
        str(planted.path),
        *DETECTORS[detector],
        "--out",
        str(out),
        "--no-progress",
    ]
    assert main(argv) == 0
    table = pd.read_csv(out / "detections.csv")
    assert (_found(table, planted.targets) <= TOLERANCE_PX).all()
    assert table["lat"].notna().all() and table["length_m"].notna().all()
    geo = json.loads((out / "detections.geojson").read_text())
    assert len(geo["features"]) == len(table)
    summary = _score(planted, out / "detections.csv", tmp_path / f"score-{detector}", detector)
    assert summary["recall"] == 1.0 and summary["tp"] == len(planted.targets)
    if detector == "ca":  # the design Pfa of 1e-8 over 2 million pixels: no false alarm
        assert summary["fp"] == 0 and summary["precision"] == 1.0


def test_scene_dataset_chips_and_truth(planted):
    ds = make_dataset(f"scene:{planted.path}?truth={planted.targets_csv}&chip=500")
    assert len(ds) == 4 * 3 and ds.items[-1] == (1500, 1000, 1600, 1300)
    seen = np.zeros((1600, 1300), np.int32)
    targets = 0
    for i in range(len(ds)):
        item = ds.truth(i)
        r0, c0, r1, c1 = item["meta"]["region"]
        seen[r0:r1, c0:c1] += 1
        inst = item["instances"][0].numpy()
        targets += int(inst.max())
        assert item["image"].shape[1:] == (r1 - r0, c1 - c0)
        assert not (item["ignore"][0].numpy() & (inst > 0)).any()
    assert (seen == 1).all()  # every pixel in exactly one chip
    assert targets == len(planted.targets)
    chip = ds[0]  # with pixels: the file's window as intensity
    from torchsar.io import open_scene

    with open_scene(planted.path, as_intensity=True) as reader:
        np.testing.assert_array_equal(chip["image"][0].numpy(), reader[0:500, 0:500])


def test_a_target_across_a_chip_border_is_ignored_in_the_neighbour(tmp_path):
    scene = write_scene_file(tmp_path / "s.tif", shape=(64, 64), tile=32, n_targets=0, pool=1)
    truth = tmp_path / "t.csv"
    truth.write_text("row,col,height,width\n31,20,3,3\n")
    ds = make_dataset(f"scene:{scene.path}?truth={truth}&chip=32")
    top, below = ds.truth(0), ds.truth(2)  # chips (0, 0) and (32, 0)
    assert top["meta"]["boxes"] == [(30, 19, 32, 22)]
    assert below["meta"]["boxes"] == [] and below["ignore"][0, 0, 19:22].all()
    assert int(below["ignore"].sum()) == 3
    items, offsets = ds.locate_points(
        np.array(["s", "s"], object), np.array([[31.0, 20.0], [40.0, 50.0]]), "p"
    )
    assert items.tolist() == [0, 3] and offsets.tolist() == [[0, 0], [32, 32]]
    with pytest.raises(EvalError, match="rows of scene 'other'"):
        ds.locate_points(np.array(["other"], object), np.array([[1.0, 1.0]]), "p")
    with pytest.raises(EvalError, match="outside"):
        ds.locate_points(np.array(["s"], object), np.array([[70.0, 1.0]]), "p")


def test_bad_truth_files(tmp_path):
    scene = write_scene_file(tmp_path / "s.tif", shape=(64, 64), tile=32, n_targets=0, pool=1)
    for text, message in [
        ("x,y\n1,2\n", "no column row"),
        ("row,col\n1.5,2\n", "whole pixel"),
        ("row,col\n100,2\n", "outside"),
        ("", "empty"),
    ]:
        bad = tmp_path / "bad.csv"
        bad.write_text(text)
        with pytest.raises(EvalError, match=message):
            make_dataset(f"scene:{scene.path}?truth={bad}")
    with pytest.raises(EvalError, match="does not exist"):
        make_dataset(f"scene:{scene.path}?truth={tmp_path / 'none.csv'}")
    with pytest.raises(EvalError, match="unknown scene option"):
        make_dataset(f"scene:{scene.path}?size=3")


_BIG = """
import json, resource, sys, time
from torchsar_eval.cli import main
t0 = time.perf_counter()
rc = main(sys.argv[1:])
print(json.dumps({"rc": rc, "wall_s": time.perf_counter() - t0,
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


@pytest.mark.slow
@pytest.mark.parametrize(
    "detector",
    [
        "ca",
        pytest.param(
            "region",
            marks=pytest.mark.xfail(
                strict=True,
                reason="known, found when CI began to run the slow tests (2026-11-28): on "
                "this 30,000 x 25,000 scene the region CFAR's tile (0, 0) is not settled at "
                "the default max_halo=512 (UnsettledError, exit 2); the same at 00ed54c",
            ),
        ),
    ],
)
def test_full_size_scene_end_to_end(tmp_path, detector):
    """The 30,000 x 25,000 uint16 BigTIFF (written here): every planted target reported at
    its pixel, the CSV scored back with recall 1; wall time and peak RSS printed."""
    t0 = time.perf_counter()
    scene = write_scene_file(tmp_path / "big.tif", n_targets=300, seed=0)
    written = time.perf_counter() - t0
    out = tmp_path / "det"
    argv = [
        "detect",
        "--scene",
        str(scene.path),
        *DETECTORS[detector],
        "--out",
        str(out),
        "--no-progress",
        "--workers",
        "2",
    ]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.run(
        [sys.executable, "-c", _BIG, *argv], capture_output=True, text=True, env=env, check=True
    )
    stats = json.loads(proc.stdout.strip().splitlines()[-1])
    workers = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(
        f"\n{detector}: scene written in {written:.0f} s; detect {stats}; largest child "
        f"process peak RSS {workers:.0f} MB"
    )
    assert stats["rc"] == 0
    table = pd.read_csv(out / "detections.csv")
    assert (_found(table, scene.targets) <= TOLERANCE_PX).all()
    summary = _score(scene, out / "detections.csv", tmp_path / "score", detector)
    assert summary["recall"] == 1.0 and summary["tp"] == 300
