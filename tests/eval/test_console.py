"""What a run prints and writes beside its tables: short dataset labels on the console, the
scored and reused images of a resumed run told apart, and ``per_image.csv`` independent of
the shard size and the worker count."""

from __future__ import annotations

import os

import numpy as np
import pandas as pd
import pytest
import torch
from skimage import io

import torchsar as ts
from torchsar_eval import evaluate
from torchsar_eval.commands.run import print_summary
from torchsar_eval.detector import Detector
from torchsar_eval.errors import EvalError
from torchsar_eval.labels import short_label, short_labels
from torchsar_eval.registry import BUILTIN
from torchsar_eval.result import Scoring
from torchsar_eval.settings import Execution

POISON = 5  # in shard 2 of 4 (shards of 2)
FAULT = "TORCHSAR_TEST_CONSOLE_FAULT"


class Chips(torch.utils.data.Dataset):
    """Eight simulated chips, generated on demand (picklable for worker processes)."""

    def __len__(self) -> int:
        return 8

    def __getitem__(self, i: int) -> dict:
        item = ts.simulate.chips(1, size=48, length_px=(10, 16), seed=7, start=i)[0]
        item["meta"] = {"name": f"chip{i}", **item["meta"]}
        return item


def fragile(x, meta=None):
    """CA-CFAR that fails on image ``POISON`` while the fault variable is set."""
    if os.environ.get(FAULT) and any(m["index"] == POISON for m in meta):
        raise RuntimeError("poisoned image")
    return BUILTIN["ca"](x)


def _run(out, shard_size=2, workers=1, detectors=None, **kwargs):
    ex = Execution(batch_size=2, shard_size=shard_size, workers=workers, progress=False)
    dets = detectors or [BUILTIN["ca"], BUILTIN["so"], BUILTIN["region"]]
    return evaluate(
        {"chips": Chips()}, dets, out=out, execution=ex, scoring=Scoring(replicates=0), **kwargs
    )


def test_short_labels_keep_the_last_path_part_and_the_options():
    long = "folder:/very/long/path/to/the/chips?type=display"
    assert short_label(long) == "folder:chips?type=display"
    names = [long, "folder:/other/place/chips?type=display", "sim-chips", "coco:/a/b/ann.json"]
    labels = short_labels(names)
    assert labels["sim-chips"] == "sim-chips" and labels["coco:/a/b/ann.json"] == "coco:ann.json"
    assert labels[long] == "folder:the/chips?type=display"
    assert len(set(labels.values())) == len(names)  # unique
    assert all(len(v) <= len(k) for k, v in labels.items())


def test_console_summary_shows_short_dataset_labels(tmp_path, capsys):
    root = tmp_path / "a" / "rather" / "long" / "path" / "to" / "the" / "data"
    root.mkdir(parents=True)
    for k in range(2):
        img, lab = np.full((32, 32), 20), np.zeros((32, 32))
        img[10 + 5 * k : 13 + 5 * k, 12:15], lab[10 + 5 * k : 13 + 5 * k, 12:15] = 255, 1
        io.imsave(root / f"c{k}.png", img.astype(np.uint8), check_contrast=False)
        io.imsave(root / f"c{k}.mask.png", lab.astype(np.uint8), check_contrast=False)
    name = f"folder:{root}?type=display"
    with pytest.warns(UserWarning):  # display-scaled images
        results = evaluate(name, ["ca"], progress=False, scoring=Scoring(replicates=0))
    print_summary(results)
    out = capsys.readouterr().out
    assert str(root) not in out
    assert "folder:data?type=display: 2 images in" in out
    assert results.summary["dataset"].tolist() == [name]  # the tables keep the full name


@pytest.mark.integration
def test_per_image_csv_is_the_same_for_any_shard_size_and_workers(tmp_path):
    files = {}
    for size, workers in [(2, 1), (256, 1), (3, 2)]:  # shard sizes, one and two workers
        out = tmp_path / f"run-{size}-{workers}"
        _run(out, shard_size=size, workers=workers)
        files[size, workers] = (out / "per_image.csv").read_bytes()
    assert len(set(files.values())) == 1
    rows = pd.read_csv(tmp_path / "run-2-1" / "per_image.csv")
    # dataset, then detector in the run's order, then image in the dataset's order
    assert list(dict.fromkeys(rows["detector"])) == ["ca", "so", "region"]
    for _, part in rows.groupby("detector", sort=False):
        assert part["image"].tolist() == [f"chip{i}" for i in range(8)]
    assert rows.groupby("detector", sort=False).ngroups == len(rows) // 8  # contiguous


def test_resumed_run_reports_scored_and_reused_images_apart(tmp_path, monkeypatch, capsys):
    out = tmp_path / "run"
    monkeypatch.setenv(FAULT, "1")
    with pytest.raises(EvalError, match="poisoned image"):
        _run(out, detectors=[Detector("fragile", fragile)])
    monkeypatch.delenv(FAULT)
    results = _run(out, detectors=[Detector("fragile", fragile)], resume=True)
    st = results.stats["chips"]
    assert (st["images"], st["scored"], st["reused"]) == (8, 4, 4)
    assert st["images_per_s"] == pytest.approx(4 / st["wall_s"])
    print_summary(results)
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("chips:"))
    assert line.startswith("chips: 4 scored in ")
    assert "4 reused from the saved run; shards 4: done 2, resumed 2" in line
    assert "4 reused from the saved run" in (out / "summary.md").read_text()


def test_a_run_without_resume_reports_all_its_images_as_scored(tmp_path):
    results = _run(tmp_path / "run")
    st = results.stats["chips"]
    assert (st["scored"], st["reused"]) == (8, 0)
    assert "reused" not in (tmp_path / "run" / "summary.md").read_text()
