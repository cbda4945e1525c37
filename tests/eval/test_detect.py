"""``torchsar-eval detect``: the table equals the library's tiled objects (and the untiled
detector's components), the same bytes for any worker count and after a kill and
``--resume``, and bad input refused in one line with exit status 2."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

import torchsar as ts
from torchsar.io import open_scene
from torchsar.simulate.scene_file import write_scene_file
from torchsar.tiling import components_table, scene_objects
from torchsar.tiling.table import detection_table
from torchsar_eval.cli import main

CA = ["--detector", "ca", "--param", "guard=4", "--param", "train=8", "--param", "pfa=1e-8"]
CA_OPTS = {"guard": 4, "train": 8, "pfa": 1e-8}


pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    path = tmp_path_factory.mktemp("detect") / "small.tif"
    return write_scene_file(
        path, shape=(700, 600), tile=128, n_targets=10, seed=3, pool=4, separation=40
    )


def _detect(scene, out: Path, *extra: str) -> int:
    return main(
        ["detect", "--scene", str(scene.path), *CA, "--out", str(out), "--no-progress", *extra]
    )


def test_table_equals_scene_objects_and_untiled_components(scene, tmp_path):
    assert _detect(scene, tmp_path / "r", "--tile", "128") == 0
    got = pd.read_csv(tmp_path / "r" / "detections.csv", dtype={"scene_id": str})
    with open_scene(scene.path, as_intensity=True) as reader:
        objects = scene_objects(reader, "ca", tile=128, **CA_OPTS)
        expect = detection_table(
            objects, "small", georef=reader.georef, pixel_spacing=reader.pixel_spacing
        )
        whole = torch.from_numpy(reader[:, :])[None, None]
    pd.testing.assert_frame_equal(got, expect, check_dtype=False)
    full = ts.cfar.ca(whole, **CA_OPTS)  # the untiled detector, one image
    ref = components_table(full.mask[0, 0].numpy(), full.statistic[0, 0].numpy())
    ints = ["peak_row", "peak_col", "area", "row_min", "row_max", "col_min", "col_max"]
    key = ["peak_row", "peak_col"]
    a = objects.sort_values(key).reset_index(drop=True)
    b = ref.sort_values(key).reset_index(drop=True)
    pd.testing.assert_frame_equal(a[ints], b[ints])
    np.testing.assert_allclose(a["score"], b["score"], rtol=1e-9)
    assert len(got) >= len(scene.targets)
    cfg = json.loads((tmp_path / "r" / "config.json").read_text())["options"]
    assert cfg["scenes"][0]["manifest"]["bytes"] == os.path.getsize(scene.path)
    assert cfg["scenes"][0]["objects"] == len(got) and cfg["tiles_total"] == 30
    assert sorted(p.name for p in (tmp_path / "r").iterdir()) == [
        ".torchsar-run.json",
        "config.json",
        "detections.csv",
        "detections.geojson",
    ]


def test_ac_scene_clutter_mean_computed_once_and_shared(scene, tmp_path, monkeypatch):
    """AC-CFAR's scene-level clutter mean: computed by the driver once and passed to every
    tile (not re-estimated per task); the table equals scene_objects'."""
    from torchsar.tiling import run as trun

    passes = []
    original = trun.scene_clutter_mean
    monkeypatch.setattr(
        trun, "scene_clutter_mean", lambda *a, **k: passes.append(1) or original(*a, **k)
    )
    opts = ["--param", "guard=2", "--param", "train=4", "--param", "pfa=1e-6"]
    argv = [
        "detect",
        "--scene",
        str(scene.path),
        "--detector",
        "ac",
        *opts,
        "--tile",
        "128",
        "--out",
        str(tmp_path / "r"),
        "--no-progress",
    ]
    assert main(argv) == 0
    assert len(passes) == 1  # 30 tiles in 8 tasks, one estimate
    got = pd.read_csv(tmp_path / "r" / "detections.csv", dtype={"scene_id": str})
    with open_scene(scene.path, as_intensity=True) as reader:
        objects = scene_objects(reader, "ac", tile=128, guard=2, train=4, pfa=1e-6)
        expect = detection_table(
            objects, "small", georef=reader.georef, pixel_spacing=reader.pixel_spacing
        )
    pd.testing.assert_frame_equal(got, expect, check_dtype=False)


def test_region_table_equals_scene_objects(scene, tmp_path):
    argv = [
        "detect",
        "--scene",
        str(scene.path),
        "--detector",
        "region",
        "--param",
        "min_size=2",
        "--tile",
        "300",
        "--out",
        str(tmp_path / "r"),
        "--no-progress",
    ]
    assert main(argv) == 0
    got = pd.read_csv(tmp_path / "r" / "detections.csv", dtype={"scene_id": str})
    with open_scene(scene.path, as_intensity=True) as reader:
        objects = scene_objects(reader, "region", tile=300, min_size=2)
        expect = detection_table(
            objects, "small", georef=reader.georef, pixel_spacing=reader.pixel_spacing
        )
    assert (objects["area"] >= 2).all() and len(objects) > 0
    pd.testing.assert_frame_equal(got, expect, check_dtype=False)


def _outputs(folder: Path) -> dict[str, bytes]:
    return {n: (folder / n).read_bytes() for n in ("detections.csv", "detections.geojson")}


def _hidden(parent: Path) -> list[Path]:
    return [p for p in parent.iterdir() if ".torchsar-partial-" in p.name and p.is_dir()]


def _kill_after_records(cmd: list[str], parent: Path, records: int) -> None:
    """Start ``cmd``, SIGKILL it once its staging folder holds ``records`` tile records."""
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            saved = [f for h in _hidden(parent) for f in h.rglob("tile-*.state")]
            if len(saved) >= records:
                break
            time.sleep(0.02)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read()


def test_same_bytes_after_an_interruption_and_resume(scene, tmp_path, monkeypatch, capsys):
    """Ctrl-C after some tiles keeps their records; ``--resume`` runs the rest and writes
    what an uninterrupted run writes, byte for byte."""
    from torchsar_eval import statefile

    tile = ["--tile", "64"]  # 11 x 10 tiles
    assert _detect(scene, tmp_path / "one", *tile) == 0
    save, calls = statefile.save, []

    def interrupted(path, data):
        if len(calls) == 25:
            raise KeyboardInterrupt
        calls.append(path)
        save(path, data)

    monkeypatch.setattr(statefile, "save", interrupted)
    out = tmp_path / "cut"
    assert _detect(scene, out, *tile) == 130
    assert "--resume" in capsys.readouterr().err
    monkeypatch.setattr(statefile, "save", save)
    assert not out.exists()
    (staging,) = _hidden(tmp_path)
    assert len(list(staging.rglob("tile-*.state"))) == 25
    assert _detect(scene, out, *tile) == 2  # neither --resume nor --discard: refused
    assert _detect(scene, out, "--tile", "128", "--resume") == 2  # other options: refused
    assert "options differ" in capsys.readouterr().err
    assert _detect(scene, out, *tile, "--resume") == 0
    assert _outputs(out) == _outputs(tmp_path / "one")
    cfg = json.loads((out / "config.json").read_text())["options"]
    assert (cfg["tiles_reused"], cfg["tiles_total"]) == (25, 110)
    assert not _hidden(tmp_path)


@pytest.mark.slow
def test_same_bytes_for_two_workers_and_after_a_kill(scene, tmp_path):
    """``--workers 2`` and a run killed with SIGKILL (then resumed) write the bytes of a
    one-process run."""
    tile = ["--tile", "32"]  # 22 x 19 tiles
    assert _detect(scene, tmp_path / "one", *tile) == 0
    assert _detect(scene, tmp_path / "two", *tile, "--workers", "2") == 0
    assert _outputs(tmp_path / "one") == _outputs(tmp_path / "two")

    out = tmp_path / "killed" / "run"
    out.parent.mkdir()
    cmd = [
        sys.executable,
        "-m",
        "torchsar_eval.cli",
        "detect",
        "--scene",
        str(scene.path),
        *CA,
        *tile,
        "--out",
        str(out),
        "--no-progress",
    ]
    _kill_after_records(cmd, out.parent, records=40)
    assert not out.exists()
    (staging,) = _hidden(out.parent)
    saved = len(list(staging.rglob("tile-*.state")))
    assert 40 <= saved < 22 * 19
    assert _detect(scene, out, *tile, "--resume", "--workers", "2") == 0
    assert _outputs(out) == _outputs(tmp_path / "one")
    cfg = json.loads((out / "config.json").read_text())["options"]
    assert cfg["tiles_reused"] >= saved and cfg["tiles_total"] == 22 * 19
    assert not _hidden(out.parent)


def _error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert err.startswith("torchsar-eval: error: ")
    return err


def test_bad_inputs_one_line_exit_2(scene, tmp_path, capsys):
    out = str(tmp_path / "out")
    base = ["detect", "--out", out, "--no-progress"]
    text = tmp_path / "notes.txt"
    text.write_text("not a scene\n")
    cases = [
        (CA, "--scene is required"),
        (["--scene", str(scene.path)], "--detector is required"),
        (["--scene", str(tmp_path / "missing.tif"), *CA], "no such file"),
        (["--scene", str(text), *CA], "neither a TIFF"),
        (["--scene", str(scene.path), "--detector", "cfar9"], "--detector must be one of"),
        (["--scene", str(scene.path), *CA, "--tile", "8"], "smaller than"),
        (["--scene", str(scene.path), *CA, "--param", "colour=3"], "unknown option"),
        (["--scene", str(scene.path), *CA, "--param", "guard"], "NAME=VALUE"),
        (["--scene", str(scene.path), *CA, "--param", "tile=64"], "use --tile"),
        (["--scene", str(scene.path), *CA, "--param", "pfa=2"], "pfa"),
        (["--scene", str(scene.path), *CA, "--engine", "ray"], "--engine ray is not supported"),
        (["--scene", str(scene.path), *CA, "--workers", "0"], "--workers"),
        (["--scene", f"{scene.path},{scene.path}", *CA], "same scene id"),
        (["--scene", str(scene.path), "--detector", "region", "--param", "max_halo=1"], "max_halo"),
        (["--scene", str(scene.path), *CA, "--device", "meta"], "holds no data"),
        (["--scene", "/proc/self/mem", *CA], "cannot be read"),
    ]
    for argv, message in cases:
        assert main([*base, *argv]) == 2, argv
        assert message in _error(capsys), argv
    assert not Path(out).exists()
    # --out: a non-empty folder that is not a run, then a previous run without --overwrite
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "x").write_text("x")
    assert _detect(scene, tmp_path / "junk") == 2
    assert "not a run" in _error(capsys)
    assert _detect(scene, tmp_path / "done", "--tile", "300") == 0
    capsys.readouterr()
    assert _detect(scene, tmp_path / "done", "--tile", "300") == 2
    assert "--overwrite" in _error(capsys)
    assert _detect(scene, tmp_path / "done", "--tile", "300", "--overwrite") == 0


def test_a_scene_without_georeferencing_writes_no_geojson(tmp_path, capsys):
    import tifffile

    rng = np.random.default_rng(0)
    amp = np.round(rng.rayleigh(6.0, size=(200, 150))).astype(np.uint16)
    amp[100, 70] = 4000
    path = tmp_path / "plain.tif"
    tifffile.imwrite(path, amp, tile=(64, 64))
    args = ["detect", "--scene", str(path), *CA, "--out", str(tmp_path / "r"), "--no-progress"]
    assert main(args) == 2  # the file does not say what its samples are
    assert "--sample-type" in _error(capsys)
    assert main([*args, "--sample-type", "amplitude"]) == 0
    assert "detections.geojson not written" in capsys.readouterr().out
    got = pd.read_csv(tmp_path / "r" / "detections.csv")
    assert (got.detect_scene_row[0], got.detect_scene_column[0]) == (100, 70)
    assert got["lat"].isna().all() and got["length_m"].isna().all()
    assert not (tmp_path / "r" / "detections.geojson").exists()


@pytest.mark.slow
def test_a_task_that_kills_its_worker_fails_alone(tmp_path):
    """The pool breaks; the tasks that were running run again one at a time, and the one
    that kills its worker again is the one blamed, by its tiles (the run stops there; saved
    records are kept for --resume)."""
    from tests.eval.detect_workers import die_on_second
    from torchsar_eval.commands.detect.plan import DetectJob, Scene
    from torchsar_eval.commands.detect.tiles import run_tasks
    from torchsar_eval.errors import EvalError

    class Bar:
        n = 0

        def update(self, k):
            self.n += k

    job = DetectJob(Scene("s", "unused.tif", (10, 40), "intensity", (1, 4)), "ca")
    tasks = [(job, [(0, j)], tmp_path) for j in range(4)]
    bar = Bar()
    with (
        pytest.warns(RuntimeWarning, match="worker process died"),
        pytest.raises(EvalError, match=r"tiles 0,1: a worker process died .* twice"),
    ):
        run_tasks(tasks, 2, bar, fn=die_on_second)
    assert bar.n >= 1  # tasks that shared the pool finished
