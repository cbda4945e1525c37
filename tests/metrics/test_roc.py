from __future__ import annotations

import numpy as np
import pytest
import torch
from sklearn.metrics import roc_curve

from torchsar.metrics import RocAccumulator, default_object_grid, default_pixel_grid, merged_grid


def _data(seed, b=3):
    g = torch.Generator().manual_seed(seed)
    target = torch.rand(b, 1, 32, 32, generator=g) < 0.1
    stat = torch.randn(b, 1, 32, 32, generator=g) + 2.0 * target
    inst = target.to(torch.int32)
    return stat, target, inst


def test_pixel_roc_matches_sklearn():
    stat, target, inst = _data(0)
    grid = torch.unique(stat.flatten().double())  # every distinct score as a threshold
    acc = RocAccumulator(grid, default_object_grid(1.0)[:1])
    acc.update(stat, target, inst)
    fpr, tpr, thr = roc_curve(target.flatten().numpy(), stat.flatten().numpy())
    curve = acc.pixel_curve()
    # sklearn: score >= thr; ours: score > t. Compare at t just below each sklearn threshold.
    for f, t, th in zip(fpr[1:], tpr[1:], thr[1:], strict=True):
        k = int(np.searchsorted(curve["threshold"], th)) - 1
        if k < 0:
            continue
        assert curve["pfa_pixel"][k] == f and curve["pd_pixel"][k] == t


def test_accumulators_add_like_one_pass():
    stat, target, inst = _data(1, b=4)
    obj = default_object_grid(1.0, n=5)
    grid = merged_grid(default_pixel_grid(), obj)
    whole = RocAccumulator(grid, obj)
    whole.update(stat, target, inst)
    a, b = RocAccumulator(grid, obj), RocAccumulator(grid, obj)
    a.update(stat[:1], target[:1], inst[:1])
    b.update(stat[1:], target[1:], inst[1:])
    merged = a + b
    assert torch.equal(merged.target_hits, whole.target_hits)
    assert torch.equal(merged.clutter_hits, whole.clutter_hits)
    for m, w in zip(merged.objects, whole.objects, strict=True):
        assert (m.images, m.instances, m.detected, m.false_alarms, m.fragments) == (
            w.images,
            w.instances,
            w.detected,
            w.false_alarms,
            w.fragments,
        )
        assert m.iou_sum == pytest.approx(w.iou_sum, rel=1e-12)  # float sum order only
    for k, v in whole.object_curve().items():
        np.testing.assert_array_equal(merged.object_curve()[k], v)


def test_ignore_and_neg_inf():
    stat = torch.tensor([[[[-torch.inf, 5.0, 0.5, 9.0]]]])
    target = torch.tensor([[[[False, True, False, False]]]])
    ignore = torch.tensor([[[[False, False, False, True]]]])
    acc = RocAccumulator(
        merged_grid(default_pixel_grid(), torch.tensor([1.0])),
        torch.tensor([1.0], dtype=torch.float64),
    )
    acc.update(stat, target, target.to(torch.int32), ignore)
    c = acc.object_curve()
    assert c["pd_pixel"][0] == 1.0 and c["pfa_pixel"][0] == 0.0
    assert c["pd_object"][0] == 1.0 and c["false_alarms_per_image"][0] == 0.0
