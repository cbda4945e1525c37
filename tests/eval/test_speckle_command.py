"""``torchsar-eval speckle`` (:mod:`torchsar_eval.experiments.speckle`) on tiny datasets."""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
import pandas as pd
import pytest
import torch
from skimage import io

from torchsar.errors import OptionError
from torchsar_eval.cli import main
from torchsar_eval.commands import load
from torchsar_eval.errors import EvalError
from torchsar_eval.experiments import speckle as command
from torchsar_eval.experiments.speckle.scoring import (
    COLUMNS,
    homogeneous_tiles,
    samples,
    score_dataset,
)


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    command.add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args(["speckle", *argv])


class FakeSim:
    """A simulated-looking dataset: two flat halves, one bright target, exponential speckle."""

    def __init__(self, n: int = 2, size: int = 96) -> None:
        g = torch.Generator().manual_seed(0)
        clean = torch.ones(n, 1, size, size)
        clean[..., size // 2 + 8 :] = 4.0  # an edge inside a column of 16-pixel tiles
        clean[..., 40:46, 20:30] = 300.0
        image = clean * torch.empty_like(clean).exponential_(generator=g)
        mask = clean > 100
        self.items = [
            {
                "image": image[i],
                "clean": clean[i],
                "mask": mask[i],
                "instances": mask[i].int(),
                "ignore": torch.zeros_like(mask[i]),
                "meta": {"clutter": {"looks": 1.0}, "boxes": [(40, 20, 46, 30)]},
            }
            for i in range(n)
        ]

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, i: int) -> dict:
        return self.items[i]


def test_score_dataset_on_simulated_like_data():
    items = list(samples(FakeSim()))
    assert items[0].clean is not None and items[0].looks == 1.0
    df = score_dataset("fake", items, ["lee", "enhanced_frost"], [5, 7], tile=16)
    assert list(df.columns) == COLUMNS
    assert list(df["filter"]) == ["none", "lee", "lee", "enhanced_frost", "enhanced_frost"]
    none, filtered = df.iloc[0], df.iloc[1:]
    assert none.enl == pytest.approx(1.0, abs=0.25)  # 1-look speckle
    assert (none.ratio_mean, none.ratio_var, none.edge_ratio) == (1.0, 0.0, 1.0)
    assert (filtered.enl > 3 * none.enl).all()
    assert (filtered.psnr_db > none.psnr_db).all() and (filtered.ssim > none.ssim).all()
    assert filtered[["epi", "ms_per_mpix"]].notna().all().all()
    assert (filtered.ratio_mean - 1).abs().max() < 0.15


def test_homogeneous_tiles_avoid_targets_and_edges():
    s = next(samples(FakeSim(n=1)))
    sel = homogeneous_tiles(s, tile=16).reshape(6, 6)
    assert not sel[2, 1]  # the target's tile
    assert not sel[:, 3].any()  # the tiles across the edge
    assert sel.sum() == 36 - 1 - 6


@pytest.fixture
def tiny_folder(tmp_path):
    root = tmp_path / "data"
    root.mkdir()
    rng = np.random.default_rng(0)
    for k in range(2):
        amp = np.sqrt(rng.exponential(size=(64, 64))) * 40
        amp[20:24, 30:34] = 250
        lab = np.zeros((64, 64))
        lab[20:24, 30:34] = 1
        io.imsave(root / f"c{k}.png", np.clip(amp, 0, 255).astype(np.uint8), check_contrast=False)
        io.imsave(root / f"c{k}.mask.png", lab.astype(np.uint8), check_contrast=False)
    return root


def test_command_on_folder(tiny_folder, tmp_path, capsys):
    out = tmp_path / "out"
    dataset = f"folder:{tiny_folder}"
    opts = ["--filters", "lee,frost", "--windows", "3,5", "--tile", "16", "--out", str(out)]
    args = _parse(["--dataset", dataset, *opts])
    assert command.run(args) == 0
    df = pd.read_csv(out / "speckle.csv")
    assert list(df.columns) == COLUMNS and len(df) == 5
    assert df[["epi", "psnr_db", "ssim"]].isna().all().all()  # no clean image
    assert df[["enl", "ratio_mean", "ratio_var", "edge_ratio"]].notna().all().all()
    assert (out / "speckle_folder_data.png").stat().st_size > 1000
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["options"]["filters"] == ["lee", "frost"] and cfg["options"]["windows"] == [3, 5]
    assert "speckle.csv" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--filters", "lee,median"], "unknown filter"),
        (["--windows", "4"], "odd integers"),
        (["--windows", "a"], "comma-separated"),
        (["--looks", "0"], "looks"),
        (["--looks", "inf"], "looks must be finite"),
        (["--filters", ","], "at least one filter"),
        (["--n", "-1"], "n must be >= 0"),
    ],
)
def test_command_errors(argv, match, tmp_path):
    with pytest.raises((EvalError, OptionError), match=match):
        command.run(_parse([*argv, "--out", str(tmp_path / "o")]))
    assert not (tmp_path / "o").exists()


def test_enl_nan_without_tiles():
    items = list(samples(FakeSim(n=1, size=24)))
    df = score_dataset("tiny", items, ["lee"], [3], tile=32)
    assert math.isnan(df.enl.iloc[1])


def test_command_on_simulated_scenes(tmp_path):
    out = tmp_path / "sim"
    opts = ["--n", "1", "--filters", "enhanced_frost", "--windows", "5", "--out", str(out)]
    assert command.run(_parse(["--dataset", "sim-scenes", *opts])) == 0
    df = pd.read_csv(out / "speckle.csv")
    assert df.notna().all().all()  # every metric, clean ones included
    none, filt = df.iloc[0], df.iloc[1]
    assert filt.enl > 5 * none.enl and filt.psnr_db > none.psnr_db
    assert (out / "speckle_sim-scenes.png").exists()


def test_one_home_and_a_typed_entry(tiny_folder, tmp_path):
    """``load("speckle")`` is the package; below the argparse edge, plain typed options."""
    assert load("speckle") is command
    opts = command.SpeckleOptions(
        datasets=[f"folder:{tiny_folder}"],
        filters=["lee"],
        windows=[3],
        looks=None,
        n=None,
        seed=0,
        tile=16,
        out=tmp_path / "typed",
    )
    assert command.evaluate(opts) == 0
    assert len(pd.read_csv(tmp_path / "typed" / "speckle.csv")) == 2


@pytest.mark.parametrize("argv", [["--n", "-1"], ["--looks", "inf"], ["--filters", "median"]])
def test_cli_user_errors_exit_2_with_one_line(argv, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["speckle", "--dataset", "sim-chips", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("torchsar-eval: error: ")
    assert not out.exists()
