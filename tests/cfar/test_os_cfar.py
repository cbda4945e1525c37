"""OS CFAR: exact order statistic (against sorting and scipy.ndimage.rank_filter), Rohling's
factor, the border rank rule."""

from __future__ import annotations

import importlib.util
from functools import partial

import numpy as np
import pytest
import torch
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy import ndimage

import torchsar as ts
from tests.reference.cfar import kth_smallest, os_alpha, ring_cells
from torchsar.cfar.thresholds import os_factor
from torchsar.errors import OptionError


def ring_footprint(guard: int, train: int) -> np.ndarray:
    o = guard + train
    fp = np.ones((2 * o + 1, 2 * o + 1), bool)
    fp[train : train + 2 * guard + 1, train : train + 2 * guard + 1] = False
    return fp


class TestOS:
    def test_smoke(self):
        x = torch.rand(1, 1, 20, 20)
        d = ts.cfar.os(x, guard=1, train=2)
        assert torch.equal(d.mask, d.statistic > d.threshold)
        assert d.threshold.item() == pytest.approx(os_factor(40, 30, 1e-3))

    @pytest.mark.parametrize("b", [0, 1, 2])
    def test_batch_invariance(self, b):
        x = torch.rand(b, 2, 16, 18, generator=torch.Generator().manual_seed(b))
        d = ts.cfar.os(x, guard=1, train=2)
        assert d.statistic.shape == x.shape
        for i in range(b):
            torch.testing.assert_close(
                d.statistic[i : i + 1], ts.cfar.os(x[i : i + 1], guard=1, train=2).statistic
            )

    def test_rank_errors(self):
        x = torch.rand(1, 1, 16, 16)
        with pytest.raises(OptionError, match="rank"):
            ts.cfar.os(x, guard=1, train=2, rank=41)
        with pytest.raises(OptionError, match="rank"):
            ts.cfar.os(x, guard=1, train=2, rank=0)

    def test_non_contiguous(self):
        x = torch.rand(1, 1, 24, 20, dtype=torch.float64).transpose(-1, -2)
        d = ts.cfar.os(x, guard=1, train=2)
        assert d.statistic.dtype == torch.float64
        torch.testing.assert_close(
            d.statistic, ts.cfar.os(x.contiguous(), guard=1, train=2).statistic
        )

    @settings(max_examples=15, deadline=None)
    @given(
        h=st.integers(7, 24),
        w=st.integers(7, 24),
        guard=st.integers(0, 2),
        train=st.integers(1, 3),
        frac=st.floats(0.0, 1.0),
        ties=st.booleans(),
        seed=st.integers(0, 2**16),
    )
    def test_every_pixel_equals_reference(self, h, w, guard, train, frac, ties, seed):
        o = guard + train
        assume(2 * o + 1 <= min(h, w))
        rng = np.random.default_rng(seed)
        img = rng.integers(0, 4, (h, w)).astype(float) if ties else rng.exponential(size=(h, w))
        n_full = (2 * o + 1) ** 2 - (2 * guard + 1) ** 2
        rank = max(1, round(frac * n_full))
        d = ts.cfar.os(torch.from_numpy(img)[None, None], guard=guard, train=train, rank=rank)
        full = os_factor(n_full, rank, 1e-3)
        for i in range(h):
            for j in range(w):
                cells = ring_cells(img, i, j, guard, train)
                rn = min(len(cells), max(1, round(rank * len(cells) / n_full)))
                est = kth_smallest(cells, rn)
                ref = img[i, j] / est if est > 0 else (np.inf if img[i, j] > 0 else 0.0)
                ref *= full / os_factor(len(cells), rn, 1e-3) if len(cells) != n_full else 1.0
                assert d.statistic[0, 0, i, j].item() == pytest.approx(ref, rel=1e-10)

    def test_equals_scipy_rank_filter(self):
        x = ts.cfar.os  # noqa: F841 - keep the name close to the assertion
        img = np.random.default_rng(0).exponential(size=(96, 80)).astype(np.float32)
        g, t = 2, 4
        n = (2 * (g + t) + 1) ** 2 - (2 * g + 1) ** 2
        r = round(3 * n / 4)
        ref = ndimage.rank_filter(img, r - 1, footprint=ring_footprint(g, t))
        d = ts.cfar.os(torch.from_numpy(img)[None, None], guard=g, train=t)
        o = g + t
        est = img[o:-o, o:-o] / ref[o:-o, o:-o]
        got = d.statistic[0, 0, o:-o, o:-o].numpy()
        np.testing.assert_array_equal(got, est.astype(np.float32))

    def test_valid_mask_excludes_cells(self):
        img = np.random.default_rng(1).exponential(size=(15, 15))
        valid = np.ones_like(img, dtype=bool)
        valid[4, 3:9] = False
        d = ts.cfar.os(
            torch.from_numpy(img)[None, None],
            guard=1,
            train=2,
            rank=10,
            valid=torch.from_numpy(valid)[None, None],
        )
        assert d.statistic[0, 0, 4, 5].item() == -np.inf
        cells = np.asarray(
            [
                img[7 + a, 6 + b]
                for a in range(-3, 4)
                for b in range(-3, 4)
                if max(abs(a), abs(b)) > 1 and valid[7 + a, 6 + b]
            ]
        )
        rn = max(1, round(10 * len(cells) / 40))
        ref = (
            img[7, 6]
            / kth_smallest(cells, rn)
            * os_factor(40, 10, 1e-3)
            / os_factor(len(cells), rn, 1e-3)
        )
        assert d.statistic[0, 0, 7, 6].item() == pytest.approx(ref, rel=1e-10)


@pytest.mark.parametrize(
    ("n", "rank", "pfa"), [(24, 18, 1e-3), (144, 108, 1e-4), (10, 1, 1e-2), (50, 50, 1e-6)]
)
def test_os_factor_matches_product_formula(n, rank, pfa):
    assert os_factor(n, rank, pfa) == pytest.approx(os_alpha(n, rank, pfa), rel=1e-9)


@pytest.mark.skipif(importlib.util.find_spec("numba") is None, reason="numba is not installed")
@pytest.mark.parametrize(("guard", "train", "rank"), [(2, 4, None), (1, 2, 1), (3, 9, 500)])
def test_compiled_path_equals_the_torch_path(guard, train, rank):
    """The CPU order statistic compiled with numba (the default when installed) and the
    torch algorithms give the same statistic, mask and threshold, bit for bit."""
    from torchsar import _jit

    x = ts.simulate.chips(3, seed=4).image
    valid = torch.rand(x.shape, generator=torch.Generator().manual_seed(1)) > 0.05
    for vm in (None, valid):
        a = ts.cfar.os(x, guard=guard, train=train, rank=rank, valid=vm)
        old, _jit.ENABLED = _jit.ENABLED, False
        try:
            b = ts.cfar.os(x, guard=guard, train=train, rank=rank, valid=vm)
        finally:
            _jit.ENABLED = old
        assert torch.equal(a.statistic, b.statistic) and torch.equal(a.mask, b.mask)
        assert torch.equal(a.threshold, b.threshold)


def _adversarial(seed: int, shape=(2, 2, 33, 47)) -> torch.Tensor:
    """Exponential clutter, a bright target, zero patches (with ``-0.0``), subnormal and
    huge values, and small integers (many equal values and exact ratio ties)."""
    g = torch.Generator().manual_seed(seed)
    x = torch.empty(shape).exponential_(generator=g)
    x[0, 0, 5:9, 5:9] *= 80.0
    x[0, 1, 8:20, 8:20] = -0.0
    x[0, 1, 14, 14] = 2.0
    x[1, 0] = torch.randint(0, 4, shape[-2:], generator=g).float()
    x[1, 1, :10] = 1e-44  # subnormal
    x[1, 1, -10:] = 3e38
    return x


@pytest.mark.parametrize(
    ("guard", "train", "rank"), [(2, 4, None), (1, 2, 1), (1, 2, 24), (0, 3, 9)]
)
@pytest.mark.parametrize("pfa", [1e-1, 1e-3, 1e-6])
def test_os_mask_by_counting_is_the_mask_of_os(guard, train, rank, pfa):
    """``os_mask`` counts the ring below the largest passing value instead of forming the
    order statistic: exactly ``os(...).mask``, borders, ties, zeros and extremes included."""
    x = _adversarial(guard * 10 + train)
    want = ts.cfar.os(x, guard=guard, train=train, rank=rank, pfa=pfa).mask
    got = ts.cfar.os_mask(x, guard=guard, train=train, rank=rank, pfa=pfa)
    assert got.dtype == torch.bool and torch.equal(got, want) and want.any()


@pytest.mark.skipif(importlib.util.find_spec("numba") is None, reason="numba is not installed")
@pytest.mark.parametrize("thr", [0.0, -0.0, -1.0, 1e-45, 0.5, 2.0, 3.0, 1e38, float("inf")])
def test_the_counting_kernel_decides_as_the_statistic_at_any_threshold(thr):
    """The compiled counting decision against the compiled statistic over the same float32
    threshold: zero, negative, tiny, exact-tie, huge and infinite thresholds (the bisection
    and the guess's neighbourhood both)."""
    from torchsar.cfar import _kernels
    from torchsar.cfar.core import geometric_scale
    from torchsar.cfar.os_cfar import _factor, _geometry
    from torchsar.order_statistics import ring_order_statistic
    from torchsar.windows import Ring

    x = _adversarial(7, shape=(2, 2, 21, 26))
    ring, rank = Ring(1, 2), 12
    h, w = x.shape[-2:]
    counts, ranks = _geometry(h, w, ring, rank)
    scale = geometric_scale(h, w, ring, partial(_factor, n_full=ring.n, rank=rank, pfa=1e-3))
    planes = x.reshape(-1, h, w).contiguous()
    est = ring_order_statistic(x, ring, ranks).reshape(-1, h, w)
    stat = np.empty(planes.shape, dtype=np.float32)
    _kernels.os_ratio(planes.numpy(), est.numpy(), counts[None], ring.n, scale, stat)
    got = np.empty(planes.shape, dtype=np.bool_)
    t = np.float32(thr)
    _kernels.os_decision(
        planes.numpy(), ring.outer, ring.guard, counts, ranks.numpy(), scale, t, got
    )
    assert np.array_equal(got, stat > t)
    if thr in (2.0, 3.0):
        assert (stat == t).any()  # exact ties are there


def test_os_mask_keeps_the_other_paths():
    """float64 images and a ``valid`` mask take ``os(...).mask``; bad input is refused with
    os_mask's name."""
    x = _adversarial(3)
    valid = torch.ones_like(x, dtype=torch.bool)
    valid[..., :5, :] = False
    assert torch.equal(ts.cfar.os_mask(x, valid=valid), ts.cfar.os(x, valid=valid).mask)
    assert torch.equal(ts.cfar.os_mask(x.double()), ts.cfar.os(x.double()).mask)
    assert ts.cfar.os_mask(torch.empty(0, 1, 16, 16)).shape == (0, 1, 16, 16)


@pytest.mark.skipif(importlib.util.find_spec("numba") is None, reason="numba is not installed")
def test_the_counting_kernel_without_ring_cells_and_with_a_float64_threshold():
    """Called directly (``os_mask`` refuses images smaller than the ring first): a pixel
    whose ring has no cell in the image (rank 0) is never detected, and a float64 threshold
    is met as its float32 rounding, as the statistic meets it."""
    from torchsar.cfar import _kernels

    x = np.ones((1, 2, 2), dtype=np.float32)
    out = np.empty(x.shape, dtype=np.bool_)
    zeros = np.zeros((2, 2), dtype=np.int64)
    _kernels.os_decision(x, 2, 1, zeros, zeros, np.ones(17), np.float32(0.5), out)
    assert not out.any()
    x = np.full((1, 5, 5), 0.1, dtype=np.float32)
    counts = np.full((5, 5), 8, dtype=np.int64)
    ones = np.ones((5, 5), dtype=np.int64)
    x[0, 2, 2] = np.float32(0.1) * np.float32(0.1)  # I / x = 0.1f exactly where all are 0.1f
    _kernels.os_decision(
        x, 1, 0, counts, ones, np.ones(9), np.float64(0.1), out := np.empty(x.shape, np.bool_)
    )
    want = np.empty(x.shape, dtype=np.bool_)
    _kernels.os_decision(x, 1, 0, counts, ones, np.ones(9), np.float32(0.1), want)
    assert np.array_equal(out, want)


def test_a_pfa_beyond_the_float_range_is_refused_by_name():
    """rank 1 of 144 cells at pfa 1e-320 needs alpha ~ 1.4e322: not a float64 threshold."""
    x = torch.ones(1, 1, 16, 16)
    with pytest.raises(OptionError, match=r"pfa=1e-320 is too small for OS-CFAR"):
        ts.cfar.os(x, rank=1, pfa=1e-320)
