"""Despeckling metrics against numpy / scipy / scikit-image references."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

import torchsar as ts
from torchsar.errors import InputValueError, OptionError, ShapeError
from torchsar.metrics.despeckling import (
    edge_preservation,
    edge_ratio,
    enl,
    psnr,
    ratio_moments,
    ssim,
)


def _pair(seed: int, shape=(2, 3, 24, 20)) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    clean = torch.rand(shape, generator=g, dtype=torch.float64) * 5
    noisy = clean * torch.empty(shape, dtype=torch.float64).exponential_(generator=g)
    return clean, noisy


class TestENL:
    def test_against_numpy(self):
        _, noisy = _pair(0)
        mask = torch.rand(noisy.shape[-2:], generator=torch.Generator().manual_seed(1)) > 0.3
        got = enl(noisy, mask=mask)
        for b in range(2):
            for c in range(3):
                v = noisy[b, c].numpy()[mask.numpy()]
                assert got[b, c].item() == pytest.approx(v.mean() ** 2 / v.var(), rel=1e-12)

    def test_gamma_speckle_has_enl_looks(self):
        looks = 4.0
        gamma = torch.distributions.Gamma(torch.tensor(looks), torch.tensor(looks))
        torch.manual_seed(0)
        x = gamma.sample((1, 1, 256, 256))
        assert enl(x).item() == pytest.approx(looks, rel=0.05)

    def test_filter_raises_enl(self):
        torch.manual_seed(1)
        x = torch.empty(1, 1, 128, 128).exponential_()
        assert enl(ts.speckle.lee(x, window=7)).item() > 5 * enl(x).item()

    def test_errors(self):
        with pytest.raises(ShapeError, match="mask"):
            enl(torch.ones(1, 1, 4, 4), mask=torch.ones(3, 3, dtype=torch.bool))


class TestRatio:
    def test_against_numpy(self):
        clean, noisy = _pair(2)
        filt = clean.clone()
        filt[0, 0, :2] = 0.0  # excluded pixels
        mean, var = ratio_moments(filt, noisy)
        f, n = filt[0, 0].numpy(), noisy[0, 0].numpy()
        r = n[f > 0] / f[f > 0]
        assert mean[0, 0].item() == pytest.approx(r.mean(), rel=1e-12)
        assert var[0, 0].item() == pytest.approx(r.var(), rel=1e-12)

    def test_ideal_filter_leaves_speckle(self):
        g = torch.Generator().manual_seed(3)
        clean = torch.rand(1, 1, 256, 256, generator=g) + 0.5
        noisy = clean * torch.empty_like(clean).exponential_(generator=g)
        mean, var = ratio_moments(clean, noisy)
        assert mean.item() == pytest.approx(1.0, abs=0.02)
        assert var.item() == pytest.approx(1.0, abs=0.05)  # 1 / L for L = 1


class TestEdges:
    def test_epi_against_scipy_laplace(self):
        clean, noisy = _pair(4)
        filt = ts.speckle.enhanced_frost(noisy, window=5)
        got = edge_preservation(filt, clean)
        for b in range(2):
            lf = ndimage.laplace(filt[b, 0].numpy())[1:-1, 1:-1]
            ls = ndimage.laplace(clean[b, 0].numpy())[1:-1, 1:-1]
            want = np.corrcoef(lf.ravel(), ls.ravel())[0, 1]
            assert got[b, 0].item() == pytest.approx(want, rel=1e-10)

    def test_epi_invariant_to_affine_change(self):
        clean, _ = _pair(5)
        want = torch.ones(2, 3, dtype=torch.float64)
        torch.testing.assert_close(edge_preservation(3 * clean + 2, clean), want)

    def test_edge_ratio(self):
        _, noisy = _pair(6)
        assert (edge_ratio(noisy, noisy) == 1).all()
        assert (edge_ratio(ts.speckle.lee(noisy, window=5), noisy) < 1).all()
        f, n = ts.speckle.kuan(noisy, window=3)[1, 2].numpy(), noisy[1, 2].numpy()

        def tv(a):
            return np.abs(np.diff(a, axis=0)).sum() + np.abs(np.diff(a, axis=1)).sum()

        got = edge_ratio(ts.speckle.kuan(noisy, window=3), noisy)[1, 2].item()
        assert got == pytest.approx(tv(f) / tv(n), rel=1e-12)
        assert edge_ratio(noisy / 2 + 1, noisy)[0, 0].item() == pytest.approx(0.5)


class TestConstantAndZeroImages:
    """One rule: a ratio's limit where it has one, NaN where the quantity has no value, an
    error when the caller can fix the cause (see the module docstring)."""

    zero = torch.zeros(2, 1, 16, 16, dtype=torch.float64)
    const = torch.full((2, 1, 16, 16), 3.0, dtype=torch.float64)

    def test_enl(self):
        assert torch.isinf(enl(self.const)).all()  # no speckle left
        assert torch.isnan(enl(self.zero)).all()  # no signal
        assert torch.isnan(enl(self.const, mask=torch.zeros(16, 16, dtype=torch.bool))).all()

    def test_ratio_moments(self):
        mean, var = ratio_moments(self.const, self.const)
        assert (mean == 1).all() and (var == 0).all()
        mean, var = ratio_moments(self.zero, self.const)  # no pixel with estimate > 0
        assert torch.isnan(mean).all() and torch.isnan(var).all()
        mean, _ = ratio_moments(self.const, self.zero)
        assert (mean == 0).all()

    def test_edge_ratio(self):
        _, noisy = _pair(8, shape=(2, 1, 16, 16))
        assert (edge_ratio(self.const, self.zero) == 1).all()  # no edges in either
        assert (edge_ratio(self.zero, self.zero) == 1).all()
        assert (edge_ratio(self.const, noisy) == 0).all()
        assert torch.isinf(edge_ratio(noisy, self.const)).all()

    def test_edge_preservation(self):
        clean, _ = _pair(9, shape=(2, 1, 16, 16))
        assert torch.isnan(edge_preservation(self.const, clean)).all()
        assert torch.isnan(edge_preservation(clean, self.zero)).all()

    @pytest.mark.parametrize("metric", [psnr, ssim])
    def test_psnr_ssim_need_a_data_range_for_a_constant_clean_image(self, metric):
        clean, _ = _pair(10, shape=(2, 1, 16, 16))
        clean[1] = 3.0
        with pytest.raises(
            InputValueError, match="clean image 1 channel 0 is constant.*data_range"
        ):
            metric(clean, clean)
        assert torch.isfinite(ssim(self.const, self.zero, data_range=1.0)).all()
        assert torch.isinf(psnr(self.const, self.const, data_range=1.0)).all()
        assert psnr(self.zero, self.const, data_range=3.0).eq(0.0).all()  # MSE 9, range 3
        torch.testing.assert_close(
            ssim(self.const, self.const, data_range=1.0), torch.ones(2, 1, dtype=torch.float64)
        )


class TestFidelity:
    @settings(max_examples=10, deadline=None)
    @given(seed=st.integers(0, 1000), data_range=st.sampled_from([None, 2.0, 10.0]))
    def test_psnr_ssim_match_skimage(self, seed, data_range):
        clean, noisy = _pair(seed, shape=(2, 1, 23, 17))
        p = psnr(noisy, clean, data_range=data_range)
        s = ssim(noisy, clean, data_range=data_range)
        for b in range(2):
            c, n = clean[b, 0].numpy(), noisy[b, 0].numpy()
            rng = float(c.max() - c.min()) if data_range is None else data_range
            want_p = peak_signal_noise_ratio(c, n, data_range=rng)
            want_s = structural_similarity(
                c,
                n,
                data_range=rng,
                gaussian_weights=True,
                sigma=1.5,
                use_sample_covariance=False,
            )
            assert p[b, 0].item() == pytest.approx(want_p, rel=1e-10)
            assert s[b, 0].item() == pytest.approx(want_s, rel=1e-8, abs=1e-10)

    def test_identity_and_dtype(self):
        clean, _ = _pair(7, shape=(1, 2, 16, 16))
        assert torch.isinf(psnr(clean, clean)).all()
        torch.testing.assert_close(ssim(clean, clean), torch.ones(1, 2, dtype=torch.float64))
        assert ssim(clean.float(), clean.float()).dtype == torch.float32
        assert psnr(clean[:0], clean[:0]).shape == (0, 2)

    def test_errors(self):
        a = torch.ones(1, 1, 16, 16)
        with pytest.raises(ShapeError, match="same shape"):
            psnr(a, torch.ones(1, 1, 16, 15))
        with pytest.raises(OptionError, match="data_range"):
            psnr(a, a, data_range=0.0)
        with pytest.raises(InputValueError, match="11x11"):
            ssim(torch.ones(1, 1, 8, 8), torch.ones(1, 1, 8, 8))
