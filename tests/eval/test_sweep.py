"""Tests of the window sweep used by ``compare-region``."""

from __future__ import annotations

import torch

from torchsar_eval.detector import Detector
from torchsar_eval.experiments.compare_region.sweep import best_setting, window_grid
from torchsar_eval.registry import BUILTIN
from torchsar_eval.runner import run_detectors


def _batch(seed: int) -> dict:
    g = torch.Generator().manual_seed(seed)
    x = torch.empty(2, 1, 48, 48).exponential_(generator=g)
    inst = torch.zeros(2, 1, 48, 48, dtype=torch.int32)
    for i, (r, c) in enumerate([(10, 12), (30, 25)]):
        x[i, 0, r : r + 6, c : c + 6] += 60.0
        inst[i, 0, r : r + 6, c : c + 6] = 1
    meta = [{"name": f"{seed}/{i}"} for i in range(2)]
    zeros = torch.zeros_like(inst, dtype=torch.bool)
    return {"image": x, "mask": inst > 0, "instances": inst, "ignore": zeros, "meta": meta}


def test_window_grid_is_the_product():
    grid = window_grid([1, 2], [3], [1e-3, 1e-4])
    assert len(grid) == 4 and {"guard": 2, "train": 3, "pfa": 1e-4} in grid


def test_best_setting_scores_match_a_direct_run():
    batches = [_batch(0), _batch(1)]
    grid = window_grid([1, 4], [2, 4], [1e-2, 1e-6])
    choice = best_setting(BUILTIN["ca"], grid, batches)
    assert {k: choice.params[k] for k in ("guard", "train", "pfa")} in grid
    items = [{k: v[i] for k, v in b.items()} for b in batches for i in range(2)]
    spec = Detector("ca", BUILTIN["ca"].fn, choice.params)
    (direct,) = run_detectors(items, [spec], batch_size=2, progress=False)
    metrics = direct.objects.metrics()
    assert (metrics["fom"], metrics["mean_iou"]) == (
        choice.scores["fom"],
        choice.scores["mean_iou"],
    )
    assert choice.scores["fom"] > 0.5  # a 6x6 target 60x above the clutter is found


def test_windows_larger_than_the_images_are_skipped():
    choice = best_setting(BUILTIN["ca"], window_grid([1, 40], [2], [1e-3]), [_batch(0)])
    assert choice.params["guard"] == 1
