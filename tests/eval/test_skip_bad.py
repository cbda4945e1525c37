"""``skip_bad`` skips images, not shards: an image a detector fails on (smaller than its
window, NaN samples) is skipped and named, every other image of its batch and shard is
scored as if the bad one were not there; a run with no image left, or more skipped than
``max_bad`` allows, fails instead of publishing."""

from __future__ import annotations

import pytest
import torch

import torchsar as ts
from torchsar_eval import evaluate
from torchsar_eval.errors import EvalError
from torchsar_eval.settings import Execution

POINTS = ["tp", "fp", "fn", "precision", "recall", "f1", "ap50", "false_alarms_per_image"]


class Chips(torch.utils.data.Dataset):
    """Simulated chips; those in ``tiny`` are 8 x 8 (smaller than CA-CFAR's window), those
    in ``nan`` hold a NaN sample; ``keep`` selects items (the reference without them)."""

    def __init__(self, keep=range(8), tiny=(), nan=()) -> None:
        self.keep, self.tiny, self.nan = list(keep), set(tiny), set(nan)

    def __len__(self) -> int:
        return len(self.keep)

    def __getitem__(self, i: int) -> dict:
        j = self.keep[i]
        item = ts.simulate.chips(1, size=48, length_px=(10, 16), seed=7, start=j)[0]
        if j in self.tiny:
            item = {k: v[..., :8, :8] if torch.is_tensor(v) else v for k, v in item.items()}
        if j in self.nan:
            item["image"][0, 20, 20] = float("nan")
        item["meta"] = {"name": f"chip{j}", **item["meta"]}
        return item


def _run(ds, batch_size=4, **ex):
    execution = Execution(batch_size=batch_size, shard_size=4, progress=False, **ex)
    return evaluate({"chips": ds}, ["ca", "region"], execution=execution)


@pytest.mark.parametrize("batch_size", [1, 4])
def test_bad_images_are_skipped_alone_and_named(batch_size):
    bad = Chips(tiny=[2], nan=[5])
    results = _run(bad, batch_size, skip_bad=True)
    good = _run(Chips(keep=[0, 1, 3, 4, 6, 7]))
    assert results.summary["images"].tolist() == [6, 6]
    assert results.summary[POINTS].equals(good.summary[POINTS])
    skipped = results.stats["chips"]["skipped_items"]
    assert [s["file"] for s in skipped] == ["chip2", "chip5"]
    assert "window" in skipped[0]["error"] and "NaN" in skipped[1]["error"]
    assert results.stats["chips"]["failed"] == []  # no shard lost


def test_without_skip_bad_the_first_bad_image_stops_the_run():
    with pytest.raises(Exception, match="(?i)window|nan"):
        _run(Chips(nan=[5]))


def test_a_run_with_every_image_failed_is_not_a_success():
    with pytest.raises(EvalError, match="dataset chips: 8 of 8 images failed, the first chip0"):
        _run(Chips(nan=range(8)), skip_bad=True)


def test_max_bad_bounds_the_share_of_skipped_images():
    with pytest.raises(EvalError, match=r"2 of 8 images failed \(more than max_bad=0.2\)"):
        _run(Chips(tiny=[2], nan=[5]), skip_bad=True, max_bad=0.2)
    assert _run(Chips(tiny=[2], nan=[5]), skip_bad=True, max_bad=0.25).summary["images"][0] == 6
    with pytest.raises(EvalError, match="max_bad=1.5: must be a share from 0 to 1"):
        Execution(max_bad=1.5)


def test_the_command_line_exits_2_when_no_image_is_left(tmp_path, capsys):
    from torchsar_eval.cli import main

    data = tmp_path / "data"
    data.mkdir()
    for name in ("a", "b"):
        (data / f"{name}.png").write_bytes(b"not a png")
        (data / f"{name}.mask.png").write_bytes(b"not a png")
    code = main(
        [
            "run",
            "--dataset",
            f"folder:{data}",
            "--detectors",
            "ca",
            "--skip-bad",
            "--out",
            str(tmp_path / "out"),
            "--no-progress",
        ]
    )
    err = capsys.readouterr().err.strip()
    assert code == 2 and "2 of 2 images failed" in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "out").exists()
