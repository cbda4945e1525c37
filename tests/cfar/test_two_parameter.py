from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st
from scipy import stats

import torchsar as ts
from tests.reference.cfar_basic import two_parameter_statistic
from tests.reference.windows import interior
from torchsar.errors import OptionError


def _expo(seed, shape, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    return torch.empty(shape, dtype=dtype).exponential_(generator=g)


class TestTwoParameter:
    @given(
        guard=st.integers(0, 3),
        train=st.integers(1, 3),
        extra=st.integers(0, 5),
        seed=st.integers(0, 999),
    )
    def test_interior_equals_brute_force(self, guard, train, extra, seed):
        o = guard + train
        h = w = 2 * o + 1 + extra
        x = 100.0 + _expo(seed, (1, 1, h, w))
        d = ts.cfar.two_parameter(x, guard=guard, train=train)
        img = x[0, 0].numpy()
        rs, cs = interior(h, w, o)
        for i in range(rs.start, rs.stop):
            for j in range(cs.start, cs.stop):
                np.testing.assert_allclose(
                    d.statistic[0, 0, i, j].item(),
                    two_parameter_statistic(img, i, j, guard, train),
                    rtol=1e-9,
                    atol=1e-9,
                )

    def test_threshold(self):
        x = _expo(0, (1, 1, 20, 20))
        assert ts.cfar.two_parameter(x, pfa=1e-3).threshold.item() == pytest.approx(
            stats.norm.ppf(1 - 1e-3)
        )
        d = ts.cfar.two_parameter(x, k=0.25)
        assert d.threshold.item() == 0.25
        assert torch.equal(d.mask, d.statistic > 0.25)

    def test_measured_pfa_gaussian_clutter(self):
        g = torch.Generator().manual_seed(1)
        x = 50 + torch.randn(4, 1, 256, 256, generator=g)
        d = ts.cfar.two_parameter(x, guard=2, train=8, pfa=1e-2)
        rate = d.mask[..., 10:-10, 10:-10].float().mean().item()
        assert 0.7e-2 < rate < 1.4e-2  # finite-N sigma estimate widens the tails slightly

    def test_constant_ring_no_nan(self):
        x = torch.full((1, 1, 15, 15), 2.0)
        x[0, 0, 7, 7] = 5.0
        d = ts.cfar.two_parameter(x, guard=1, train=2)
        assert not torch.isnan(d.statistic).any()
        assert d.statistic[0, 0, 7, 7] == torch.inf
        assert d.mask.sum() == 1

    def test_batch_invariant_and_float32(self):
        x = _expo(3, (4, 1, 48, 48), torch.float32)
        whole = ts.cfar.two_parameter(x)
        assert whole.statistic.dtype == torch.float32
        for i in range(4):
            assert torch.equal(
                ts.cfar.two_parameter(x[i : i + 1]).statistic, whole.statistic[i : i + 1]
            )

    def test_errors(self):
        with pytest.raises(OptionError, match="k must be"):
            ts.cfar.two_parameter(torch.ones(1, 1, 20, 20), k=-1.0)


def test_input_is_not_modified():
    x = _expo(9, (1, 1, 30, 30))
    before = x.clone()
    ts.cfar.two_parameter(x)
    assert torch.equal(x, before)
