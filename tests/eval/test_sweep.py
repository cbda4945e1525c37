"""Tests of the window sweep used by ``compare-region``."""

from __future__ import annotations

import torch

from eval.detectors import DETECTORS
from eval.sweep import best_setting, window_grid
from torchsar.metrics import object_counts


def _batch(seed: int) -> dict:
    g = torch.Generator().manual_seed(seed)
    x = torch.empty(2, 1, 48, 48).exponential_(generator=g)
    inst = torch.zeros(2, 1, 48, 48, dtype=torch.int32)
    for i, (r, c) in enumerate([(10, 12), (30, 25)]):
        x[i, 0, r : r + 6, c : c + 6] += 60.0
        inst[i, 0, r : r + 6, c : c + 6] = 1
    return {"image": x, "instances": inst, "ignore": torch.zeros_like(inst, dtype=torch.bool)}


def test_window_grid_is_the_product():
    grid = window_grid([1, 2], [3], [1e-3, 1e-4])
    assert len(grid) == 4 and {"guard": 2, "train": 3, "pfa": 1e-4} in grid


def test_best_setting_scores_match_a_direct_run():
    batches = [_batch(0), _batch(1)]
    grid = window_grid([1, 4], [2, 4], [1e-2, 1e-6])
    choice = best_setting(DETECTORS["ca"], grid, batches)
    assert {k: choice.params[k] for k in ("guard", "train", "pfa")} in grid
    direct = sum(
        (object_counts(DETECTORS["ca"].fn(b["image"], **choice.params).mask, b["instances"])
         for b in batches),
        start=type(choice.counts)(),
    )  # fmt: skip
    assert direct == choice.counts
    assert choice.counts.fom > 0.5  # a 6x6 target 60x above the clutter is found


def test_windows_larger_than_the_images_are_skipped():
    choice = best_setting(DETECTORS["ca"], window_grid([1, 40], [2], [1e-3]), [_batch(0)])
    assert choice.params["guard"] == 1
