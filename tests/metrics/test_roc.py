from __future__ import annotations

import numpy as np
import pytest
import torch
from sklearn.metrics import roc_curve

from torchsar import _jit
from torchsar._checks import InputTypeError, InputValueError, ShapeError
from torchsar.metrics import RocAccumulator, default_pixel_grid, pixel_counts
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


def _extreme_values(ppd, dtype):
    """Grid values, their float neighbours, zeros, infinities, subnormals and a wide random
    sweep; and the grid in ``dtype``."""
    grid = default_pixel_grid(ppd).to(dtype)
    g = torch.Generator().manual_seed(ppd)
    on = torch.cat([grid, torch.nextafter(grid, grid + 1), torch.nextafter(grid, grid - 1)])
    special = torch.tensor([0.0, -0.0, torch.inf, -torch.inf, 1e-45, -1e-45, 1e-30, 3e38])
    sweep = torch.randn(20000, generator=g, dtype=torch.float64) * 10 ** (
        torch.rand(20000, generator=g, dtype=torch.float64) * 18 - 9
    )
    return torch.cat([on, special.to(dtype), sweep.to(dtype)]), grid


@pytest.mark.parametrize("ppd", [10, 40, 50])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_log_grid_bins_equal_bucketize(ppd, dtype):
    log_grid = LogGrid.matching(default_pixel_grid(ppd))
    assert log_grid is not None
    x, grid = _extreme_values(ppd, dtype)
    assert torch.equal(log_grid.bucketize(x, grid), torch.bucketize(x, grid))


@pytest.mark.skipif(not _jit.enabled(), reason="numba kernels not available")
@pytest.mark.parametrize("ppd", [10, 40])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("with_ignore", [False, True])
def test_compiled_histogram_equals_bucketize_counts(ppd, dtype, with_ignore):
    x, grid = _extreme_values(ppd, dtype)
    g = torch.Generator().manual_seed(7)
    target = torch.rand(x.shape, generator=g) < 0.3
    ignore = (torch.rand(x.shape, generator=g) < 0.2) if with_ignore else None
    cls = (~target).long() if ignore is None else (~target).long().masked_fill(ignore, 2)
    n = grid.numel() + 1
    literal = torch.bincount(cls * n + torch.bucketize(x, grid), minlength=3 * n).view(3, n)
    acc = RocAccumulator(default_pixel_grid(ppd))
    assert torch.equal(acc._compiled_histogram(x, target, ignore), literal)


def test_update_is_the_same_with_and_without_the_compiled_kernel(monkeypatch):
    stat, target = _data(5)
    ignore = torch.zeros_like(target)
    ignore[0, 0, :3] = True
    out = []
    for on in (True, False):
        monkeypatch.setattr(_jit, "ENABLED", on)
        acc = RocAccumulator()
        acc.update(stat, target, ignore)
        acc.update(stat.double() * 3, target)
        out.append(acc)
    assert torch.equal(out[0].target_hits, out[1].target_hits)
    assert torch.equal(out[0].clutter_hits, out[1].clutter_hits)
    assert (out[0].targets, out[0].clutter) == (out[1].targets, out[1].clutter)


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


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("with_ignore", [False, True])
@pytest.mark.parametrize("compiled", [True, False])
def test_update_with_a_mask_returns_its_pixel_counts(monkeypatch, dtype, with_ignore, compiled):
    if compiled and not _jit.enabled():
        pytest.skip("numba kernels not available")
    monkeypatch.setattr(_jit, "ENABLED", compiled)
    x, _ = _extreme_values(40, dtype)
    x = x[torch.isfinite(x) | x.isinf()].reshape(1, 1, 1, -1)
    g = torch.Generator().manual_seed(11)
    target = torch.rand(x.shape, generator=g) < 0.3
    ignore = (torch.rand(x.shape, generator=g) < 0.2) if with_ignore else None
    detected = x > 1.0
    one, two = RocAccumulator(), RocAccumulator()
    got = one.update(x, target, ignore, detected=detected)
    two.update(x, target, ignore)
    assert got == pixel_counts(detected, target, ignore=ignore)
    for k in ("target_hits", "clutter_hits", "targets", "clutter"):
        a, b = getattr(one, k), getattr(two, k)
        assert torch.equal(a, b) if isinstance(a, torch.Tensor) else a == b, k
    assert RocAccumulator().update(x, target, ignore) is None


def test_a_nan_is_refused_before_anything_is_added():
    acc = RocAccumulator()
    stat = torch.tensor([[[[1.0, float("nan"), 3.0]]]])
    tgt = torch.zeros(1, 1, 1, 3, dtype=torch.bool)
    with pytest.raises(InputValueError, match="NaN"):
        acc.update(stat, tgt, detected=stat > 0)
    assert acc.targets == acc.clutter == 0 and int(acc.clutter_hits.sum()) == 0
    with pytest.raises(InputTypeError, match="detected"):
        acc.update(stat.nan_to_num(), tgt, detected=stat)
