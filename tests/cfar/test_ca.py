from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

import torchsar as ts
from tests.reference.cfar_basic import binomial_interval, ca_alpha, ca_statistic
from tests.reference.windows import interior
from torchsar.cfar.thresholds import ca_factor
from torchsar.errors import (
    InputTypeError,
    InputValueError,
    OptionError,
    ShapeError,
    WindowSizeError,
)


def _expo(seed, shape, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    return torch.empty(shape, dtype=dtype).exponential_(generator=g)


class TestCA:
    def test_smoke(self):
        d = ts.cfar.ca(_expo(0, (2, 1, 32, 32)))
        assert d.mask.shape == d.statistic.shape == (2, 1, 32, 32)
        assert d.mask.dtype == torch.bool
        assert torch.equal(d.mask, d.statistic > d.threshold)

    @given(
        guard=st.integers(0, 3),
        train=st.integers(1, 3),
        extra=st.integers(0, 5),
        seed=st.integers(0, 999),
    )
    def test_interior_equals_brute_force(self, guard, train, extra, seed):
        o = guard + train
        h = w = 2 * o + 1 + extra
        x = _expo(seed, (1, 1, h, w))
        d = ts.cfar.ca(x, guard=guard, train=train, pfa=1e-3)
        img = x[0, 0].numpy()
        rs, cs = interior(h, w, o)
        for i in range(rs.start, rs.stop):
            for j in range(cs.start, cs.stop):
                np.testing.assert_allclose(
                    d.statistic[0, 0, i, j].item(),
                    ca_statistic(img, i, j, guard, train),
                    rtol=1e-12,
                )

    def test_border_pixels_keep_their_own_pfa(self):
        # A border pixel with n cells is detected iff I / mean_ring > alpha(n).
        x = _expo(1, (1, 1, 12, 12))
        d = ts.cfar.ca(x, guard=1, train=2, pfa=1e-2)
        img = x[0, 0].numpy()
        from tests.reference.windows import ring_cells

        for i, j in [(0, 0), (0, 5), (11, 3), (6, 11)]:
            cells = ring_cells(img, i, j, 1, 2)
            expected = img[i, j] / cells.mean() > ca_alpha(cells.size, 1e-2)
            assert d.mask[0, 0, i, j].item() == expected
            scaled = (
                img[i, j]
                / cells.mean()
                * ca_alpha(7 * 7 - 3 * 3, 1e-2)
                / ca_alpha(cells.size, 1e-2)
            )
            np.testing.assert_allclose(d.statistic[0, 0, i, j].item(), scaled, rtol=1e-9)

    @pytest.mark.parametrize("n", [8, 24, 144])
    @pytest.mark.parametrize("looks", [1.0, 2.0, 4.0])
    def test_threshold_factor_is_the_f_quantile(self, n, looks):
        np.testing.assert_allclose(ca_factor(n, 1e-3, looks), ca_alpha(n, 1e-3, looks), rtol=1e-8)

    def test_measured_pfa_on_exponential_clutter(self):
        x = _expo(7, (4, 1, 512, 512), torch.float32)
        d = ts.cfar.ca(x, guard=2, train=4, pfa=1e-3)
        inner = d.mask[..., 6:-6, 6:-6]
        lo, hi = binomial_interval(inner.numel(), 1e-3)
        assert lo <= inner.float().mean().item() <= hi

    def test_measured_pfa_on_gamma_clutter_with_looks(self):
        g = torch.Generator().manual_seed(3)
        x = torch._standard_gamma(torch.full((4, 1, 512, 512), 4.0), generator=g) / 4.0
        d = ts.cfar.ca(x, guard=2, train=4, pfa=1e-3, looks=4.0)
        inner = d.mask[..., 6:-6, 6:-6]
        lo, hi = binomial_interval(inner.numel(), 1e-3)
        assert lo <= inner.float().mean().item() <= hi

    @pytest.mark.parametrize("b", [0, 1, 3])
    def test_batch_invariant(self, b):
        x = _expo(2, (3, 2, 40, 40), torch.float32)
        whole = ts.cfar.ca(x)
        part = ts.cfar.ca(x[:b])
        assert torch.equal(part.statistic, whole.statistic[:b])

    def test_dtype_and_noncontiguous(self):
        x = _expo(4, (1, 1, 40, 60), torch.float32)
        d = ts.cfar.ca(x.transpose(-1, -2))
        assert d.statistic.dtype == torch.float32
        ref = ts.cfar.ca(x.transpose(-1, -2).contiguous())
        assert torch.equal(d.statistic, ref.statistic)

    def test_zero_and_constant_images_no_nan(self):
        for x in (torch.zeros(1, 1, 20, 20), torch.full((1, 1, 20, 20), 3.0)):
            d = ts.cfar.ca(x)
            assert not torch.isnan(d.statistic).any()
            assert not d.mask.any()
        x = torch.zeros(1, 1, 20, 20)
        x[0, 0, 10, 10] = 1.0
        d = ts.cfar.ca(x, guard=1, train=2)
        assert d.mask[0, 0, 10, 10] and d.mask.sum() == 1

    def test_valid_mask(self):
        x = _expo(5, (1, 1, 30, 30))
        valid = torch.ones_like(x, dtype=torch.bool)
        valid[..., :, :10] = False
        x_bright = x.clone()
        x_bright[..., :, :10] = 1e6  # no-data filled with junk must not matter
        d1 = ts.cfar.ca(x, valid=valid)
        d2 = ts.cfar.ca(x_bright, valid=valid)
        torch.testing.assert_close(d1.statistic, d2.statistic)
        assert torch.isneginf(d1.statistic[..., :, :10]).all()

    def test_errors(self):
        with pytest.raises(WindowSizeError, match="guard=2 \\+ train=4"):
            ts.cfar.ca(torch.ones(1, 1, 10, 10))
        with pytest.raises(ShapeError):
            ts.cfar.ca(torch.ones(10, 10))
        with pytest.raises(InputTypeError):
            ts.cfar.ca(torch.ones(1, 1, 20, 20, dtype=torch.complex64))
        with pytest.raises(InputValueError):
            ts.cfar.ca(-torch.ones(1, 1, 20, 20))
        with pytest.raises(OptionError, match="pfa"):
            ts.cfar.ca(torch.ones(1, 1, 20, 20), pfa=2.0)
        with pytest.raises(OptionError, match="guard"):
            ts.cfar.ca(torch.ones(1, 1, 20, 20), guard=-1)
