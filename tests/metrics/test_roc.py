from __future__ import annotations

import numpy as np
import pytest
import torch
from sklearn.metrics import roc_curve

from torchsar._checks import InputTypeError, ShapeError
from torchsar.metrics import RocAccumulator, default_pixel_grid


def _data(seed, b=3):
    g = torch.Generator().manual_seed(seed)
    target = torch.rand(b, 1, 32, 32, generator=g) < 0.1
    stat = torch.randn(b, 1, 32, 32, generator=g) + 2.0 * target
    return stat, target


def test_pixel_roc_matches_sklearn():
    stat, target = _data(0)
    grid = torch.unique(stat.flatten().double())  # every distinct score as a threshold
    acc = RocAccumulator(grid)
    acc.update(stat, target)
    fpr, tpr, thr = roc_curve(target.flatten().numpy(), stat.flatten().numpy())
    curve = acc.pixel_curve()
    # sklearn: score >= thr; ours: score > t. Compare at t just below each sklearn threshold.
    for f, t, th in zip(fpr[1:], tpr[1:], thr[1:], strict=True):
        k = int(np.searchsorted(curve["threshold"], th)) - 1
        if k < 0:
            continue
        assert curve["pfa_pixel"][k] == f and curve["pd_pixel"][k] == t


def test_accumulators_add_like_one_pass():
    stat, target = _data(1, b=4)
    whole = RocAccumulator()
    whole.update(stat, target)
    a, b = RocAccumulator(), RocAccumulator()
    a.update(stat[:1], target[:1])
    b.update(stat[1:], target[1:])
    merged = a + b
    assert torch.equal(merged.target_hits, whole.target_hits)
    assert torch.equal(merged.clutter_hits, whole.clutter_hits)
    with pytest.raises(ValueError, match="different threshold grids"):
        _ = a + RocAccumulator(default_pixel_grid(10))


def test_ignore_and_neg_inf():
    stat = torch.tensor([[[[-torch.inf, 5.0, 0.5, 9.0]]]])
    target = torch.tensor([[[[False, True, False, False]]]])
    ignore = torch.tensor([[[[False, False, False, True]]]])
    acc = RocAccumulator(torch.tensor([1.0], dtype=torch.float64))
    acc.update(stat, target, ignore)
    c = acc.pixel_curve()
    assert c["pd_pixel"][0] == 1.0 and c["pfa_pixel"][0] == 0.0
    assert (acc.targets, acc.clutter) == (1, 2)


def test_update_validates():
    acc = RocAccumulator()
    with pytest.raises(InputTypeError, match="target"):
        acc.update(torch.zeros(1, 1, 2, 2), torch.zeros(1, 1, 2, 2))
    with pytest.raises(ShapeError):
        acc.update(torch.zeros(1, 1, 2, 2), torch.zeros(1, 1, 2, 3, dtype=torch.bool))
