from __future__ import annotations

import math

import numpy as np
import torch

from tests.reference.motion import czt as czt_ref
from torchsar.motion import czt


class TestCZT:
    def test_equals_fft(self):
        a = torch.randn(4, 16, dtype=torch.complex128)
        y = czt(a, torch.tensor(-2 * math.pi / 16, dtype=torch.float64), 16)
        torch.testing.assert_close(y, torch.fft.fft(a))

    def test_per_row_alpha_matches_direct_sum(self):
        g = torch.Generator().manual_seed(1)
        a = torch.randn(3, 11, dtype=torch.complex128, generator=g)
        alpha = torch.tensor([0.013, -0.2, 1.7], dtype=torch.float64)
        y = czt(a, alpha, 37)
        for r in range(3):
            ref = czt_ref(a[r].numpy(), float(alpha[r]), 37)
            np.testing.assert_allclose(y[r].numpy(), ref, atol=1e-10)

    def test_complex64_and_empty_batch(self):
        a = torch.randn(0, 8, dtype=torch.complex64)
        assert czt(a, torch.tensor(0.1), 5).shape == (0, 5)
        b = torch.randn(2, 8, dtype=torch.complex64)
        assert czt(b, torch.tensor(0.1), 5).dtype == torch.complex64
