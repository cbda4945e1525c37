from __future__ import annotations

import numpy as np
import pytest
import torch
from sklearn.metrics import roc_curve

from torchsar._checks import InputTypeError, InputValueError, ShapeError
from torchsar.metrics import RocAccumulator, default_pixel_grid
from torchsar.metrics.log_bins import LogGrid


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
    with pytest.raises(InputValueError, match="NaN"):
        acc.update(torch.tensor([[[[0.0, torch.nan]]]]), torch.zeros(1, 1, 1, 2, dtype=torch.bool))
    with pytest.raises(ShapeError):
        acc.update(torch.zeros(1, 1, 2, 2), torch.zeros(1, 1, 2, 3, dtype=torch.bool))


@pytest.mark.parametrize("ppd", [10, 40, 50])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_log_grid_bins_equal_bucketize(ppd, dtype):
    grid64 = default_pixel_grid(ppd)
    log_grid = LogGrid.matching(grid64)
    assert log_grid is not None
    grid = grid64.to(dtype)
    g = torch.Generator().manual_seed(ppd)
    # grid values, their float neighbours, zeros, infinities, subnormals and a wide random sweep
    on = torch.cat([grid, torch.nextafter(grid, grid + 1), torch.nextafter(grid, grid - 1)])
    special = torch.tensor([0.0, -0.0, torch.inf, -torch.inf, 1e-45, -1e-45, 1e-30, 3e38])
    sweep = torch.randn(20000, generator=g, dtype=torch.float64) * 10 ** (
        torch.rand(20000, generator=g, dtype=torch.float64) * 18 - 9
    )
    x = torch.cat([on, special.to(dtype), sweep.to(dtype)])
    assert torch.equal(log_grid.bucketize(x, grid), torch.bucketize(x, grid))


def test_log_grid_recognises_only_its_grid():
    assert LogGrid.matching(torch.tensor([1.0], dtype=torch.float64)) is None
    assert LogGrid.matching(default_pixel_grid(10) * 2) is None


def test_update_counts_equal_literal_exceedances():
    stat, target = _data(3)
    stat = stat * 10.0 ** torch.randint(
        -4, 6, stat.shape, generator=torch.Generator().manual_seed(4)
    )
    ignore = torch.zeros_like(target)
    ignore[1] = True
    acc = RocAccumulator()
    acc.update(stat, target, ignore)
    grid = acc.pixel_grid.float()
    above = stat.flatten()[:, None] > grid[None, :]
    for kind, hits in ((target, acc.target_hits), (~target, acc.clutter_hits)):
        keep = (kind & ~ignore).flatten()[:, None]
        assert torch.equal(hits, (above & keep).sum(0))
    assert acc.targets == int((target & ~ignore).sum())
    assert acc.clutter == int((~target & ~ignore).sum())
