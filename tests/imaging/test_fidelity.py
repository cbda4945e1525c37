from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from torchsar.errors import ShapeError
from torchsar.imaging.fidelity import align, magnitude_correlation, phase_rmse


class TestAlignment:
    def test_shift_and_flip(self):
        gen = torch.Generator().manual_seed(0)
        ref = torch.rand(2, 1, 8, 8, generator=gen)
        est, c = align(ref.roll((3, -2), (-2, -1)), ref)
        torch.testing.assert_close(est, ref)
        torch.testing.assert_close(c, torch.ones(2, 1))
        twin = ref.flip(-2, -1).roll(1, -1)
        assert (magnitude_correlation(twin, ref) < 0.9).all()
        torch.testing.assert_close(magnitude_correlation(twin, ref, flip=True), torch.ones(2, 1))

    def test_matches_brute_force(self):
        gen = torch.Generator().manual_seed(1)
        a, b = torch.rand(1, 1, 5, 6, generator=gen), torch.rand(1, 1, 5, 6, generator=gen)
        best = max(
            torch.corrcoef(torch.stack([a.roll((i, j), (-2, -1)).flatten(), b.flatten()]))[0, 1]
            for i in range(5)
            for j in range(6)
        )
        assert align(a, b)[1].item() == pytest.approx(best.item(), abs=1e-5)


class TestPhaseRMSE:
    @settings(max_examples=20, deadline=None)
    @given(c=st.floats(-10, 10), s=st.floats(-3, 3), t=st.floats(-3, 3))
    def test_plane_is_unobservable(self, c, s, t):
        gen = torch.Generator().manual_seed(0)
        truth = torch.rand(1, 8, 6, generator=gen, dtype=torch.float64) * 6
        m = torch.arange(8, dtype=torch.float64)[:, None]
        k = torch.arange(6, dtype=torch.float64)
        assert phase_rmse(truth + c + s * m + t * k, truth).item() < 1e-6

    def test_wrapping(self):
        truth = torch.zeros(1, 16, dtype=torch.float64)
        est = truth + 2 * math.pi * torch.randint(-3, 4, (1, 16)).double()
        assert phase_rmse(est, truth).item() < 1e-9

    def test_known_value(self):
        truth = torch.zeros(1, 4, dtype=torch.float64)
        est = torch.tensor([[0.1, -0.1, -0.1, 0.1]], dtype=torch.float64)  # no linear part
        assert phase_rmse(est, truth).item() == pytest.approx(0.1, abs=1e-9)

    def test_errors(self):
        with pytest.raises(ShapeError, match="same shape"):
            phase_rmse(torch.zeros(1, 4), torch.zeros(1, 5))
        with pytest.raises(ShapeError, match=r"\(B, M\)"):
            phase_rmse(torch.zeros(4), torch.zeros(4))
