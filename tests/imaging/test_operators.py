from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.reference.imaging import fft2c_dense
from torchsar.errors import InputTypeError, ShapeError
from torchsar.imaging import FourierOperator, fft2c, ifft2c


def _crandn(*shape, seed=0, dtype=torch.complex128):
    g = torch.Generator().manual_seed(seed)
    return torch.randn(*shape, dtype=dtype, generator=g)


def _inner(a, b):
    return torch.sum(a.conj() * b)


class TestFFT2c:
    def test_matches_dense_reference(self):
        x = _crandn(5, 6, seed=1)
        np.testing.assert_allclose(fft2c(x).numpy(), fft2c_dense(x.numpy()), atol=1e-12)

    def test_inverse_and_unitary(self):
        x = _crandn(2, 3, 8, 7)
        torch.testing.assert_close(ifft2c(fft2c(x)), x)
        torch.testing.assert_close(fft2c(x).norm(), x.norm())

    def test_centre_impulse_is_flat(self):
        x = torch.zeros(4, 6, dtype=torch.complex64)
        x[2, 3] = 1
        torch.testing.assert_close(fft2c(x), torch.full((4, 6), 24**-0.5, dtype=torch.complex64))

    def test_real_input_and_dtype(self):
        assert fft2c(torch.ones(4, 4)).dtype == torch.complex64
        assert fft2c(torch.ones(4, 4, dtype=torch.float64)).dtype == torch.complex128

    def test_empty_batch(self):
        assert fft2c(torch.zeros(0, 4, 4)).shape == (0, 4, 4)

    def test_non_contiguous(self):
        x = _crandn(8, 6).transpose(0, 1)
        torch.testing.assert_close(fft2c(x), fft2c(x.contiguous()))

    def test_exceptions(self):
        with pytest.raises(InputTypeError, match=r"torch\.Tensor"):
            fft2c(np.ones((4, 4)))
        with pytest.raises(ShapeError, match="at least 2 dims"):
            ifft2c(torch.ones(4))
        with pytest.raises(InputTypeError, match="floating or complex"):
            fft2c(torch.ones(4, 4, dtype=torch.int64))


class TestFourierOperator:
    @settings(max_examples=15, deadline=None)
    @given(
        m=st.integers(1, 9),
        k=st.integers(1, 9),
        b=st.integers(0, 3),
        masked=st.booleans(),
        seed=st.integers(0, 1000),
    )
    def test_adjoint(self, m, k, b, masked, seed):
        mask = (
            (torch.rand(m, k, generator=torch.Generator().manual_seed(seed)) > 0.3)
            if masked
            else None
        )
        op = FourierOperator((m, k), mask=mask)
        f = _crandn(b, 1, m, k, seed=seed)
        g = _crandn(b, m, k, seed=seed + 1)
        lhs = _inner(op.forward(f), g)
        rhs = _inner(f, op.adjoint(g))
        torch.testing.assert_close(lhs, rhs, atol=1e-10, rtol=1e-10)

    def test_gram_identity_flag(self):
        assert FourierOperator((4, 4)).gram_is_identity
        op = FourierOperator((4, 4), mask=torch.ones(4, 4, dtype=torch.bool))
        assert not op.gram_is_identity

    def test_shapes_and_batch(self):
        op = FourierOperator((6, 5))
        for b in (0, 1, 2):
            f = _crandn(b, 1, 6, 5)
            assert op.forward(f).shape == (b, 6, 5)
            assert op.adjoint(op.forward(f)).shape == (b, 1, 6, 5)

    def test_masked_samples_are_zero(self):
        mask = torch.zeros(4, 4, dtype=torch.bool)
        mask[:2] = True
        g = FourierOperator((4, 4), mask=mask).forward(_crandn(1, 1, 4, 4))
        assert torch.all(g[:, 2:] == 0)

    def test_batched_mask(self):
        mask = torch.rand(2, 4, 4, generator=torch.Generator().manual_seed(3)) > 0.5
        op = FourierOperator((4, 4), mask=mask)
        f = _crandn(2, 1, 4, 4)
        single = FourierOperator((4, 4), mask=mask[1]).forward(f[1:])
        torch.testing.assert_close(op.forward(f)[1:], single)

    def test_check_data(self):
        op = FourierOperator((4, 4))
        with pytest.raises(ShapeError, match=r"\(B, 4, 4\)"):
            op.check_data(torch.zeros(1, 4, 5, dtype=torch.complex64))
        with pytest.raises(InputTypeError, match="complex"):
            op.check_data(torch.zeros(1, 4, 4))

    def test_mask_errors(self):
        with pytest.raises(InputTypeError, match="bool"):
            FourierOperator((4, 4), mask=torch.ones(4, 4))
        with pytest.raises(ShapeError, match="mask must have shape"):
            FourierOperator((4, 4), mask=torch.ones(3, 4, dtype=torch.bool))
