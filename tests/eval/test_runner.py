from __future__ import annotations

import pandas as pd
import pytest
import torch

from torchsar.errors import InputValueError
from torchsar_eval.registry import BUILTIN
from torchsar_eval.runner import run_detectors


class ListDataset(torch.utils.data.Dataset):
    def __init__(self, images):
        self.images = images

    def __len__(self):
        return len(self.images)

    def __getitem__(self, i):
        img = self.images[i]
        return {
            "image": img,
            "mask": torch.zeros_like(img, dtype=torch.bool),
            "instances": torch.zeros_like(img, dtype=torch.int32),
            "ignore": torch.zeros_like(img, dtype=torch.bool),
            "meta": {"name": str(i)},
        }


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -1.0])
def test_bad_pixels_raise_typed_error(bad):
    img = torch.ones(1, 32, 32)
    img[0, 3, 3] = bad
    with pytest.raises(InputValueError):
        run_detectors(ListDataset([img]), [BUILTIN["ca"]], progress=False)


def test_results_do_not_depend_on_batch_size():
    g = torch.Generator().manual_seed(0)
    imgs = [torch.empty(1, 40, 40).exponential_(generator=g) for _ in range(5)]
    imgs.insert(2, torch.empty(1, 30, 30).exponential_(generator=g))  # a size change mid-batch
    runs = [
        run_detectors(ListDataset(imgs), [BUILTIN["ca"]], batch_size=b, progress=False)[0]
        for b in (1, 4, 16)
    ]
    for r in runs[1:]:
        assert r.pixels == runs[0].pixels
        assert r.objects == runs[0].objects
        assert torch.equal(r.roc.clutter_hits, runs[0].roc.clutter_hits)


def test_empty_dataset():
    (res,) = run_detectors(ListDataset([]), [BUILTIN["ca"]], progress=False)
    assert res.images == 0 and res.roc.targets == 0 and res.objects.images == 0
    assert res.objects.metrics()["tp"] == 0


def test_preprocess_runs_before_detectors():
    seen = []

    def stage(x):
        seen.append(x.shape)
        return x * 0 + 1.0  # flat image: CA detects nothing

    img = torch.ones(1, 32, 32)
    img[0, 16, 16] = 100.0
    (res,) = run_detectors(ListDataset([img]), [BUILTIN["ca"]], preprocess=stage, progress=False)
    assert seen == [(1, 1, 32, 32)]
    assert res.pixels.fp == 0


def test_a_detector_that_writes_into_its_input_corrupts_nothing_after_it():
    """A detector zeroing its images (and emptying the metadata) in place: ``ca`` after it,
    and the scoring, see the batch as it was (on the code before, ``ca`` lost every
    detection)."""
    import torchsar_eval as te
    from torchsar.cfar import ca

    def vandal(images, meta):
        images.mul_(0)
        for m in meta:
            m.clear()
        return ca(images + 1.0)

    alone = te.evaluate("sim-chips", ["ca"], n=6, progress=False).summary
    both = te.evaluate(
        "sim-chips", [te.Detector("vandal", vandal), "ca"], n=6, progress=False
    ).summary
    rows = both[both.detector == "ca"].drop(columns=["detector"]).reset_index(drop=True)
    pd.testing.assert_frame_equal(rows, alone.drop(columns=["detector"]).reset_index(drop=True))
    assert int(alone.tp.iloc[0]) > 0
