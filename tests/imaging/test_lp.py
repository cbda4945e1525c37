from __future__ import annotations

import pytest
import torch

from torchsar.errors import InputTypeError, OptionError, ShapeError
from torchsar.imaging import FourierOperator, default_lam, ifft2c, lp_image
from torchsar.imaging.fidelity import magnitude_correlation


class TestLpImage:
    def test_sparser_than_conventional(self, sparse_data):
        f, mask, g = sparse_data
        img = lp_image(g)
        conv = ifft2c(g).unsqueeze(1)
        assert img.shape == (4, 1, 32, 32)
        # background (off-support) energy is suppressed
        off = lambda x: (x.abs().square() * ~mask).sum() / x.abs().square().sum()  # noqa: E731
        assert off(img) < 0.2 * off(conv)
        assert (magnitude_correlation(img, f) > 0.98).all()

    def test_missing_samples_cg_path(self, sparse_data):
        f, _, g = sparse_data
        gen = torch.Generator().manual_seed(0)
        mask = torch.rand(32, 32, generator=gen) > 0.4
        op = FourierOperator((32, 32), mask=mask)
        img = lp_image(g[:2] * mask, operator=op, max_iter=30, cg_iterations=10)
        conv = op.adjoint(g[:2] * mask)
        c_lp, c_conv = magnitude_correlation(img, f[:2]), magnitude_correlation(conv, f[:2])
        assert (c_lp > c_conv + 0.05).all()
        assert (c_lp > 0.95).all()

    def test_cg_equals_closed_form_with_full_mask(self, sparse_data):
        _, _, g = sparse_data
        full = FourierOperator((32, 32), mask=torch.ones(32, 32, dtype=torch.bool))
        a = lp_image(g[:1], max_iter=5, tol=0.0)
        b = lp_image(g[:1], operator=full, max_iter=5, tol=0.0)
        torch.testing.assert_close(a, b, atol=1e-4, rtol=1e-3)

    def test_batch_invariance(self, sparse_data):
        _, _, g = sparse_data
        both = lp_image(g[:2])
        one = lp_image(g[1:2])
        torch.testing.assert_close(both[1:], one, atol=1e-5, rtol=1e-4)
        assert lp_image(g[:0]).shape == (0, 1, 32, 32)

    def test_float64(self, sparse_data):
        _, _, g = sparse_data
        assert lp_image(g[:1].to(torch.complex128), max_iter=3).dtype == torch.complex128

    def test_non_contiguous(self, sparse_data):
        _, _, g = sparse_data
        gt = g[:1].transpose(1, 2).contiguous().transpose(1, 2)
        assert not gt.is_contiguous()
        torch.testing.assert_close(lp_image(gt, max_iter=3), lp_image(g[:1], max_iter=3))

    def test_exceptions(self, sparse_data):
        _, _, g = sparse_data
        with pytest.raises(OptionError, match=r"p must be in \(0, 2\]"):
            lp_image(g, p=3.0)
        with pytest.raises(OptionError, match="lam"):
            lp_image(g, lam=-1.0)
        with pytest.raises(OptionError, match="lam must be a scalar or have B"):
            lp_image(g, lam=torch.ones(3))
        with pytest.raises(InputTypeError, match="complex"):
            lp_image(g.real)
        with pytest.raises(ShapeError, match=r"\(B, M, K\)"):
            lp_image(g, operator=FourierOperator((16, 16)))
        with pytest.raises(OptionError, match="LinearOperator"):
            lp_image(g, operator="fft")


class TestDefaultLam:
    def test_invariant_to_phase_errors(self, sparse_data):
        _, _, g = sparse_data
        op = FourierOperator((32, 32))
        phi = torch.rand(g.shape, generator=torch.Generator().manual_seed(0)) * 6
        torch.testing.assert_close(
            default_lam(g, operator=op), default_lam(g * torch.exp(1j * phi), operator=op)
        )

    def test_default_operator_is_the_unitary_fft(self, sparse_data):
        _, _, g = sparse_data
        torch.testing.assert_close(
            default_lam(g), default_lam(g, operator=FourierOperator((32, 32)))
        )
        with pytest.raises(TypeError):
            default_lam(g, FourierOperator((32, 32)))  # type: ignore[misc]

    def test_scales_with_data(self, sparse_data):
        _, _, g = sparse_data
        op = FourierOperator((32, 32))
        torch.testing.assert_close(default_lam(3 * g, operator=op), 3 * default_lam(g, operator=op))
