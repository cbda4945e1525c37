"""End-to-end tests of ``torchsar-eval run`` on tiny folder datasets with known answers."""

from __future__ import annotations

import json
import os
import shutil
import signal
import time

import numpy as np
import pandas as pd
import pytest
from skimage import io

from torchsar_eval.cli import main
from torchsar_eval.output import write_marker
from torchsar_eval.tables import FROC_COLUMNS, SUMMARY_COLUMNS


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


@pytest.mark.figures
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
    assert not list(tmp_path.glob(".out.torchsar-*"))
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


# --- one error policy: exit 2, one line, --out untouched ------------------------------


def _one_error_line(capsys) -> str:
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1, lines
    assert lines[0].startswith("torchsar-eval: error: ")
    return lines[0]


def _nothing_left(tmp_path, out):
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if ".torchsar-" in p.name]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--param", "ca.bogus=1"], "detector ca has no option 'bogus'; valid: guard"),
        (["--param", "ca.guardd=3"], "has no option 'guardd'"),
        (["--despeckle", "lee", "--despeckle-param", "bogus=5"], "lee has no option 'bogus'"),
        (["--despeckle", "lee", "--despeckle-param", "window"], "KEY=VALUE"),
        (["--param", "go.pfa=1.5"], "detector go rejects its options"),
        (["--param", "ca.looks=-1"], "detector ca rejects its options"),
        (["--param", "region.bogus=1"], "bogus"),
        (["--n", "-1"], "--n must be >= 1, got -1"),
        (["--n", "0"], "--n must be >= 1, got 0"),
        (["--n", "abc"], "argument --n: invalid int value"),
        (["--batch-size", "0"], "--batch-size must be >= 1, got 0"),
        (["--detectors", ","], "--detectors is empty"),
        (["--detectors", "ca,ca"], "more than once"),
    ],
)
def test_run_user_errors_before_any_work(tiny_folder, tmp_path, capsys, monkeypatch, args, message):
    def no_dataset(*a, **k):
        raise AssertionError("a dataset was built before the options were checked")

    monkeypatch.setattr("torchsar_eval.datasets.make_dataset", no_dataset)
    monkeypatch.setattr("torchsar_eval.api.make_dataset", no_dataset)
    out = tmp_path / "never"
    base = ["run", "--dataset", f"folder:{tiny_folder}", "--out", str(out), "--no-progress"]
    assert main(base + args) == 2
    assert message in _one_error_line(capsys)
    _nothing_left(tmp_path, out)


def _snapshot(folder) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _tiny_run(tiny_folder, out, *extra):
    argv = ["run", "--dataset", f"folder:{tiny_folder}", "--detectors", "ca", "--no-progress"]
    return main([*argv, "--out", str(out), *extra])


@pytest.mark.parametrize(
    ("prepare", "message"),
    [
        (lambda p: p.write_text("x"), "exists and is not a folder"),
        (lambda p: (p.mkdir(), (p / "mine.txt").write_text("x")), "not a run"),
        (lambda p: (p.parent / "f").write_text("x"), "is not a folder"),
    ],
)
def test_bad_out_is_refused_at_once(tiny_folder, tmp_path, capsys, monkeypatch, prepare, message):
    monkeypatch.setattr(
        "torchsar_eval.commands.run.options.check_run_args", pytest.fail
    )  # no work at all
    out = tmp_path / "out"
    prepare(out)
    target = out if out.exists() else tmp_path / "f" / "out"
    before = sorted(p.name for p in tmp_path.iterdir())
    assert _tiny_run(tiny_folder, target) == 2
    assert message in _one_error_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_previous_run_needs_overwrite_which_leaves_no_stale_file(tiny_folder, tmp_path, capsys):
    out = tmp_path / "out"
    assert _tiny_run(tiny_folder, out) == 0
    (out / "stale.csv").write_text("from an older run")  # a file only an older run wrote
    write_marker(out)  # (so the marker lists it: a file no run wrote is never deleted)
    before = _snapshot(out)
    capsys.readouterr()
    assert _tiny_run(tiny_folder, out) == 2
    assert "pass --overwrite" in _one_error_line(capsys)
    assert _snapshot(out) == before
    assert _tiny_run(tiny_folder, out, "--overwrite") == 0
    assert not (out / "stale.csv").exists() and (out / "config.json").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def _ctrl_c(*args, **kwargs):
    raise KeyboardInterrupt


def _sigterm(*args, **kwargs):
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(5)  # the handler interrupts this


class _SigtermWhenCollected:
    def __del__(self):
        os.kill(os.getpid(), signal.SIGTERM)
        sum(range(10_000))  # the handler raises in here, where Python swallows exceptions


def _sigterm_in_finalizer(*args, **kwargs):
    _SigtermWhenCollected()  # collected at once
    time.sleep(5)  # the signal sent again interrupts this


@pytest.mark.parametrize(
    ("interrupt", "code", "line"),
    [
        (_ctrl_c, 130, "torchsar-eval: interrupted"),
        (_sigterm, 143, "torchsar-eval: terminated"),
        (_sigterm_in_finalizer, 143, "torchsar-eval: terminated"),
    ],
)
def test_interrupted_run_leaves_the_previous_one_intact(
    tiny_folder, tmp_path, capsys, monkeypatch, interrupt, code, line
):
    out = tmp_path / "out"
    assert _tiny_run(tiny_folder, out) == 0
    before = _snapshot(out)
    capsys.readouterr()
    monkeypatch.setattr("torchsar_eval.api.run_shards", interrupt)
    handler = signal.getsignal(signal.SIGTERM)
    assert _tiny_run(tiny_folder, out, "--overwrite") == code
    hint = "; continue with the same command plus --resume"
    assert [x for x in capsys.readouterr().err.splitlines() if x.strip()] == [line + hint]
    assert _snapshot(out) == before
    hidden = [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert all(".torchsar-partial-" in h for h in hidden)  # kept for --resume only
    assert signal.getsignal(signal.SIGTERM) is handler


@pytest.mark.figures
def test_datasets_with_the_same_basename_are_never_mixed(tiny_folder, tmp_path, capsys):
    other = tmp_path / "elsewhere" / tiny_folder.name
    shutil.copytree(tiny_folder, other)
    shutil.rmtree(other / "sub")  # one chip here, two there
    out = tmp_path / "out"
    argv = ["--dataset", f"folder:{tiny_folder}", "--dataset", f"folder:{other}"]
    code = main(["run", *argv, "--detectors", "ca", "--no-progress", "--out", str(out)])
    assert code == 0 and len(list(out.glob("roc_*.png"))) == 2  # each keeps its own files
    assert len(list((out / "shards").iterdir())) == 2
    summary = pd.read_csv(out / "summary.csv")
    assert summary.images.tolist() == [2, 1]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--n", "0"], "--n must be >= 1"),
        (["--mstar-n", "0"], "--mstar-n must be >= 2"),
        (["--batch-size", "0"], "--batch-size must be >= 1"),
        (["--guards", "4,x"], "--guards must be comma-separated integers"),
        (["--pfas", "0.5,2"], "--pfas values must be > 0 and < 1"),
        (["--window-cfars", "ca,nope"], "unknown window CFAR 'nope'"),
        (["--guards", "100", "--window-cfars", "ca"], "no window of the grid fits"),
    ],
)
def test_compare_region_user_errors(tmp_path, capsys, args, message):
    out = tmp_path / "never"
    tiny = ["--sim", "sim-chips", "--n", "1", "--n-tune", "1", "--mstar", str(tmp_path / "no")]
    assert main(["compare-region", "--out", str(out), "--no-progress", *tiny, *args]) == 2
    assert message in _one_error_line(capsys)
    _nothing_left(tmp_path, out)


def test_compare_region_reports_mstar_on_chips_it_did_not_tune_on(tmp_path, capsys):
    root = tmp_path / "chips"
    root.mkdir()
    for k in range(6):
        img = np.full((32, 32), 20)
        img[10 + k : 13 + k, 12:15] = 255
        lab = np.zeros((32, 32))
        lab[10 + k : 13 + k, 12:15] = 1
        _write_pair(root, f"c{k}", img, lab)
    out = tmp_path / "out"
    argv = ["compare-region", "--out", str(out), "--sim", "sim-chips", "--n", "1", "--n-tune", "1"]
    argv += ["--mstar", str(root), "--guards", "2", "--trains", "4", "--pfas", "1e-3"]
    assert main([*argv, "--window-cfars", "ca", "--no-progress"]) == 0
    summary = pd.read_csv(out / "summary.csv")
    assert set(summary[summary.dataset == "mstar_sarbake"].images) == {4}  # 6 chips - c0, c5
    assert "tuned on 2 chips (every 5th), reported on the other 4" in capsys.readouterr().out


def test_every_command_has_out_and_overwrite():
    from torchsar_eval.cli import build_parser
    from torchsar_eval.commands import COMMANDS, load

    parser = build_parser()
    required = {"make-dataset": ["--kind", "sim-chips"]}
    for name in COMMANDS:
        if not getattr(load(name), "WRITES_OUT", True):  # clean: deletes, writes nothing
            continue
        args = parser.parse_args([name, *required.get(name, []), "--out", "x", "--overwrite"])
        assert (str(args.out), args.overwrite) == ("x", True), name


def test_no_overlap_writes_the_same_tables(tmp_path):
    """``--no-overlap`` (detect, then score, batch after batch) against the default (the
    next batch detected while this one is scored): every table byte for byte."""
    outs = []
    for flag in ([], ["--no-overlap"]):
        out = tmp_path / ("plain" if flag else "overlap")
        args = ["run", "--dataset", "sim-chips", "--n", "6", "--batch-size", "2", "--out"]
        assert main([*args, str(out), "--no-figures", "--no-progress", *flag]) == 0
        outs.append(out)
    tables = sorted(p.name for p in outs[0].glob("*.csv") if p.name != "timing.csv")
    assert "summary.csv" in tables and "per_image.csv" in tables
    for name in tables:
        assert (outs[0] / name).read_bytes() == (outs[1] / name).read_bytes(), name


def test_overlap_must_be_a_bool():
    from torchsar_eval.errors import EvalError
    from torchsar_eval.settings import Execution

    with pytest.raises(EvalError, match="overlap"):
        Execution(overlap="no")
