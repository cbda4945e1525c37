"""End-to-end tests of ``torchsar-eval run`` on tiny folder datasets with known answers."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from skimage import io

from eval.cli import main
from eval.tables import FROC_COLUMNS, SUMMARY_COLUMNS


def _write_pair(folder, stem, image, labels, ext="png"):
    io.imsave(folder / f"{stem}.{ext}", image.astype(np.uint8), check_contrast=False)
    io.imsave(folder / f"{stem}.mask.png", labels.astype(np.uint8), check_contrast=False)


@pytest.fixture
def tiny_folder(tmp_path):
    """Two 32x32 chips: constant clutter, one bright 3x3 target each, an ignored patch."""
    root = tmp_path / "data"
    (root / "sub").mkdir(parents=True)
    for k, folder in enumerate([root, root / "sub"]):
        img = np.full((32, 32), 20)
        lab = np.zeros((32, 32))
        r, c = 10 + 5 * k, 12
        img[r : r + 3, c : c + 3] = 255
        lab[r : r + 3, c : c + 3] = 1
        lab[25:28, 25:28] = 2
        _write_pair(folder, f"chip{k}", img, lab)
    return root


def test_run_on_folder_known_answers(tiny_folder, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(
        [
            "run",
            "--dataset",
            f"folder:{tiny_folder}",
            "--detectors",
            "ca",
            "--out",
            str(out),
            "--no-progress",
        ]
    )
    assert code == 0
    summary = pd.read_csv(out / "summary.csv")
    assert list(summary.columns) == SUMMARY_COLUMNS
    row = summary.iloc[0]
    assert (row.images, row.pd_pixel, row.pfa_pixel) == (2, 1.0, 0.0)
    assert (row.pd_object, row.false_alarms, row.fragmentation, row.mean_iou) == (1, 0, 1, 1)
    assert row.fom == 1.0
    assert (row.tp, row.fp, row.fn, row.precision, row.recall, row.f1) == (2, 0, 0, 1, 1, 1)
    assert (row.ap50, row.ap50_95, row.pd_at_1_fa_per_image) == (1, 1, 1)
    roc = pd.read_csv(out / "roc.csv")
    assert list(roc.columns) == FROC_COLUMNS and len(roc) > 0
    assert roc.pd_object.is_monotonic_increasing
    assert roc.false_alarms_per_image.is_monotonic_increasing
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["options"]["detectors"]["ca"]["guard"] == 2
    assert cfg["torchsar_version"]
    assert (out / "summary.md").read_text().startswith("# Run summary")
    assert (out / "roc_folder_data.png").stat().st_size > 0
    assert "ca" in capsys.readouterr().out


def test_param_override_is_recorded(tiny_folder, tmp_path):
    out = tmp_path / "o"
    assert (
        main(
            [
                "run",
                "--dataset",
                f"folder:{tiny_folder}",
                "--detectors",
                "two_parameter",
                "--param",
                "two_parameter.train=3",
                "--out",
                str(out),
                "--no-progress",
            ]
        )
        == 0
    )
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["options"]["detectors"]["two_parameter"]["train"] == 3


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--detectors", "nope"], "unknown detector 'nope'; valid: "),
        (["--dataset", "mnist"], "unknown dataset 'mnist'; valid: sim-chips"),
        (["--param", "ca.guard"], "DETECTOR.NAME=VALUE"),
        (["--detectors", "ca", "--param", "two_parameter.k=1"], "not being run"),
    ],
)
def test_user_errors(tiny_folder, tmp_path, capsys, args, message):
    out = tmp_path / "never"
    base = ["run", "--dataset", f"folder:{tiny_folder}", "--out", str(out), "--no-progress"]
    assert main(base + args) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def _folder_error(tmp_path, capsys, prepare):
    root = tmp_path / "bad"
    root.mkdir()
    prepare(root)
    out = tmp_path / "out"
    code = main(
        [
            "run",
            "--dataset",
            f"folder:{root}",
            "--detectors",
            "ca",
            "--out",
            str(out),
            "--no-progress",
        ]
    )
    assert code == 2
    assert not out.exists()
    assert not list(tmp_path.glob(".out.partial-*"))
    return capsys.readouterr().err


def test_empty_folder(tmp_path, capsys):
    assert "no images" in _folder_error(tmp_path, capsys, lambda r: None)


def test_missing_folder(tmp_path, capsys):
    assert (
        main(["run", "--dataset", f"folder:{tmp_path}/nothing", "--out", str(tmp_path / "o")]) == 2
    )
    assert "does not exist" in capsys.readouterr().err


def test_image_without_mask_is_named(tmp_path, capsys):
    def prep(root):
        _write_pair(root, "a", np.full((32, 32), 9), np.zeros((32, 32)))
        io.imsave(root / "lonely.png", np.zeros((32, 32), np.uint8), check_contrast=False)

    err = _folder_error(tmp_path, capsys, prep)
    assert "lonely.png has no mask" in err


def test_mask_of_another_size(tmp_path, capsys):
    def prep(root):
        io.imsave(root / "a.png", np.zeros((32, 32), np.uint8), check_contrast=False)
        io.imsave(root / "a.mask.png", np.zeros((30, 32), np.uint8), check_contrast=False)

    assert "is 32x30 but image" in _folder_error(tmp_path, capsys, prep)


def test_unreadable_image(tmp_path, capsys):
    def prep(root):
        (root / "a.png").write_bytes(b"not a png")
        io.imsave(root / "a.mask.png", np.zeros((32, 32), np.uint8), check_contrast=False)

    assert "cannot read image" in _folder_error(tmp_path, capsys, prep)


def test_window_larger_than_image(tmp_path, capsys):
    def prep(root):
        _write_pair(root, "small", np.full((8, 8), 9), np.zeros((8, 8)))

    assert "larger than the image" in _folder_error(tmp_path, capsys, prep)


def test_variant_images(tmp_path, capsys):
    root = tmp_path / "v"
    root.mkdir()
    img = np.full((32, 32), 20)
    img[10:13, 10:13] = 255
    lab = np.zeros((32, 32))
    lab[10:13, 10:13] = 1
    _write_pair(root, "x.000", img, lab, ext="jpeg")
    io.imsave(root / "x.000.linear.jpeg", img.astype(np.uint8), check_contrast=False)
    for spec in (f"folder:{root}", f"folder:{root}?variant=linear"):
        out = tmp_path / f"o{len(spec)}"
        assert (
            main(
                ["run", "--dataset", spec, "--detectors", "ca", "--out", str(out), "--no-progress"]
            )
            == 0
        )
        assert pd.read_csv(out / "summary.csv").images.iloc[0] == 1


def test_despeckle_stage_recorded(tiny_folder, tmp_path):
    out = tmp_path / "d"
    assert (
        main(
            [
                "run",
                "--dataset",
                f"folder:{tiny_folder}",
                "--detectors",
                "ca",
                "--despeckle",
                "enhanced_frost",
                "--despeckle-param",
                "window=3",
                "--out",
                str(out),
                "--no-progress",
            ]
        )
        == 0
    )
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["options"]["despeckle"] == {"filter": "enhanced_frost", "window": 3}


def test_bad_despeckle_option_fails_before_output(tiny_folder, tmp_path, capsys):
    out = tmp_path / "d"
    assert (
        main(
            [
                "run",
                "--dataset",
                f"folder:{tiny_folder}",
                "--despeckle",
                "lee",
                "--despeckle-param",
                "window=4",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    assert "window" in capsys.readouterr().err
    assert not out.exists()
