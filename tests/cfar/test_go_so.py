"""GO and SO CFAR: interior statistics against cell-by-cell references, exact factors."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import torchsar as ts
from tests.reference.cfar import block_alpha, block_cells, zero_blocks_scene
from torchsar.cfar.thresholds import block_factor
from torchsar.errors import InputValueError, OptionError, ShapeError, WindowSizeError

VARIANTS = [("go", ts.cfar.go, np.max), ("so", ts.cfar.so, np.min)]


@pytest.mark.parametrize(("name", "fn", "pick"), VARIANTS)
class TestBlockCFAR:
    def test_smoke(self, name, fn, pick):
        x = torch.rand(1, 1, 20, 20)
        d = fn(x, guard=1, train=2)
        assert d.mask.shape == x.shape and d.mask.dtype == torch.bool
        assert torch.equal(d.mask, d.statistic > d.threshold)

    @pytest.mark.parametrize("b", [0, 1, 2])
    def test_batch_invariance(self, name, fn, pick, b):
        x = torch.rand(b, 2, 16, 18, generator=torch.Generator().manual_seed(b))
        d = fn(x, guard=1, train=3)
        assert d.statistic.shape == x.shape
        for i in range(b):
            one = fn(x[i : i + 1], guard=1, train=3).statistic
            torch.testing.assert_close(d.statistic[i : i + 1], one)

    def test_exceptions(self, name, fn, pick):
        with pytest.raises(ShapeError, match=r"\(B, C, H, W\)"):
            fn(torch.rand(8, 8))
        with pytest.raises(InputValueError, match="non-negative"):
            fn(-torch.ones(1, 1, 16, 16))
        with pytest.raises(WindowSizeError):
            fn(torch.rand(1, 1, 8, 8), guard=2, train=4)
        with pytest.raises(OptionError, match="pfa"):
            fn(torch.rand(1, 1, 16, 16), pfa=1.5)

    def test_hand_computed(self, name, fn, pick):
        # g=0, t=1: blocks are top (1x2), right (2x1), bottom (1x2), left (2x1) around (2, 2)
        x = torch.zeros(1, 1, 5, 5, dtype=torch.float64)
        x[0, 0, 1, 1:3] = 1.0  # top block mean 1
        x[0, 0, 1:3, 3] = 3.0  # right block mean 3
        x[0, 0, 3, 2:4] = 5.0  # bottom mean 5
        x[0, 0, 2:4, 1] = 7.0  # left mean 7
        x[0, 0, 2, 2] = 21.0
        est = 7.0 if name == "go" else 1.0
        stat = fn(x, guard=0, train=1).statistic[0, 0, 2, 2].item()
        assert stat == pytest.approx(21.0 / est, rel=1e-12)

    def test_non_contiguous_and_dtype(self, name, fn, pick):
        x = torch.rand(1, 1, 24, 20, dtype=torch.float64).transpose(-1, -2)
        d = fn(x, guard=1, train=2)
        assert d.statistic.dtype == torch.float64
        torch.testing.assert_close(d.statistic, fn(x.contiguous(), guard=1, train=2).statistic)

    @settings(max_examples=12, deadline=None)
    @given(
        h=st.integers(8, 22),
        w=st.integers(8, 22),
        guard=st.integers(0, 2),
        train=st.integers(1, 3),
        seed=st.integers(0, 2**16),
    )
    def test_interior_equals_reference(self, name, fn, pick, h, w, guard, train, seed):
        o = guard + train
        assume(2 * o + 1 <= min(h, w))
        img = np.random.default_rng(seed).exponential(size=(h, w))
        d = fn(torch.from_numpy(img)[None, None], guard=guard, train=train)
        for i in range(o, h - o):
            for j in range(o, w - o):
                means = [b.mean() for b in block_cells(img, i, j, guard, train)]
                ref = img[i, j] / pick(means)
                assert d.statistic[0, 0, i, j].item() == pytest.approx(ref, rel=1e-10)

    def test_border_blocks_use_their_own_factor(self, name, fn, pick):
        img = np.random.default_rng(3).exponential(size=(12, 12))
        d = fn(torch.from_numpy(img)[None, None], guard=1, train=2, pfa=1e-2)
        reduce = "max" if name == "go" else "min"
        blocks = block_cells(img, 0, 5, 1, 2)  # top block empty
        sizes = tuple(sorted(len(b) for b in blocks))
        means = [b.mean() for b in blocks if len(b)]
        scale = block_factor((10, 10, 10, 10), 1e-2, reduce) / block_factor(sizes, 1e-2, reduce)
        ref = img[0, 5] / pick(means) * scale
        assert d.statistic[0, 0, 0, 5].item() == pytest.approx(ref, rel=1e-9)


@pytest.mark.parametrize("reduce", ["max", "min"])
@pytest.mark.parametrize(("m", "pfa"), [(4, 1e-2), (9, 1e-3), (36, 1e-4)])
def test_factor_matches_quadrature(reduce, m, pfa):
    assert block_factor((m, m, m, m), pfa, reduce) == pytest.approx(
        block_alpha(m, 4, pfa, reduce), rel=1e-6
    )


@pytest.mark.parametrize(("name", "fn", "pick"), VARIANTS)
@pytest.mark.parametrize("kernels", [True, False])
def test_zero_blocks_beside_bright_targets_on_the_no_data_path(
    monkeypatch, name, fn, pick, kernels
):
    """Blocks of exact zeros in an image with bright targets (a plane mean far from the
    zeros): the no-data path (a valid mask, summed as shifted integral images) gives
    statistics that are never negative and the same detections as the direct sums. Before,
    SO returned about -1e14 beside such blocks (a negative residue taken as the smallest
    mean) where the direct sums give +inf."""
    from torchsar import _jit

    monkeypatch.setattr(_jit, "ENABLED", kernels)  # the masked rules: compiled, or tensors
    for seed in range(12):
        rng = np.random.default_rng(seed)
        h, w = (int(v) for v in rng.integers(24, 48, 2))
        dtype = torch.float32 if seed % 2 else torch.float64
        img = zero_blocks_scene(rng, h, w)
        x = torch.from_numpy(img).to(dtype)
        g, t = int(rng.integers(0, 3)), int(rng.integers(1, 4))
        direct = fn(x, guard=g, train=t)
        masked = fn(x, guard=g, train=t, valid=torch.ones_like(x, dtype=torch.bool))
        assert bool((masked.statistic >= 0).all()), (name, seed)
        assert torch.equal(masked.mask, direct.mask), (name, seed)
