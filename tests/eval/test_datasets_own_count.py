"""A dataset's own ``n=N`` option: it sets that dataset's size, takes precedence over the
run-wide ``n``, and leaves the other datasets at theirs."""

from __future__ import annotations

import numpy as np
import pytest

import torchsar_eval as te
from tests.io.writers import write_png
from torchsar_eval.datasets import make_dataset
from torchsar_eval.errors import EvalError


def test_sim_datasets_take_their_own_count():
    assert len(make_dataset("sim-scenes?n=2")) == 2
    assert len(make_dataset("sim-chips?n=5", n=9)) == 5  # its own n wins
    assert len(make_dataset("sim-chips", n=9)) == 9
    assert len(make_dataset("sim-chips?n=0")) == 0  # an empty dataset is valid


def test_own_count_items_equal_the_run_wide_count():
    own, run_wide = make_dataset("sim-chips?n=3", seed=4), make_dataset("sim-chips", n=3, seed=4)
    for i in range(3):
        a, b = own[i], run_wide[i]
        assert a["meta"]["name"] == b["meta"]["name"]
        assert (a["image"] == b["image"]).all()


def test_folder_keeps_its_other_options(tmp_path):
    rng = np.random.default_rng(0)
    for i in range(4):
        write_png(tmp_path / f"c{i}.png", rng.integers(0, 255, (32, 32), dtype=np.uint8))
        write_png(tmp_path / f"c{i}.mask.png", np.zeros((32, 32), np.uint8))
    ds = make_dataset(f"folder:{tmp_path}?n=2&type=intensity")
    assert len(ds) == 2 and ds.sample_type == "intensity"
    assert [ds[i]["meta"]["name"] for i in range(2)] == [
        make_dataset(f"folder:{tmp_path}?type=intensity")[i]["meta"]["name"] for i in range(2)
    ]


@pytest.mark.parametrize("bad", ["x", "-1", "1.5", "", "²", "99999999999"])
def test_bad_own_count_is_one_line_naming_it(bad):
    with pytest.raises(EvalError, match=r"dataset option n=.* whole number"):
        make_dataset(f"sim-chips?n={bad}")


def test_one_run_mixes_counts():
    res = te.evaluate(["sim-chips?n=3", "sim-scenes?n=1"], ["ca"], n=2, progress=False)
    images = res.summary.set_index("dataset")["images"]
    assert images["sim-chips?n=3"] == 3 and images["sim-scenes?n=1"] == 1
