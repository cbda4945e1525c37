from __future__ import annotations

import numpy as np
import torch

from tests.reference.imaging import brute_force_phase
from torchsar.imaging import phase_step_1d, phase_step_2d, phase_step_separable


def _pair(seed, shape=(1, 3, 4)):
    gen = torch.Generator().manual_seed(seed)
    d = torch.randn(*shape, dtype=torch.complex128, generator=gen)
    g = torch.randn(*shape, dtype=torch.complex128, generator=gen)
    return g, d


def _wrapdiff(a, b):
    return np.abs(np.angle(np.exp(1j * (a - b))))


class TestClosedFormVsBruteForce:
    def test_1d(self):
        for seed in range(3):
            g, d = _pair(seed)
            phi = phase_step_1d(g, d)[0].numpy()
            for m in range(3):
                ref = brute_force_phase(d[0, m].numpy(), g[0, m].numpy())
                assert _wrapdiff(phi[m], ref) < 2e-3

    def test_2d(self):
        g, d = _pair(5)
        phi = phase_step_2d(g, d)[0].numpy()
        for m in range(3):
            for k in range(4):
                ref = brute_force_phase(d[0, m, k : k + 1].numpy(), g[0, m, k : k + 1].numpy())
                assert _wrapdiff(phi[m, k], ref) < 2e-3

    def test_separable_rows_then_cols(self):
        g, d = _pair(7)
        cols0 = torch.tensor([[0.3, -1.0, 2.0, 0.5]], dtype=torch.float64)
        rows, cols = phase_step_separable(g, d, cols0)
        dn, gn = d[0].numpy(), g[0].numpy()
        for m in range(3):
            ref = brute_force_phase(dn[m] * np.exp(1j * cols0[0].numpy()), gn[m])
            assert _wrapdiff(rows[0, m].item(), ref) < 2e-3
        for k in range(4):
            ref = brute_force_phase(dn[:, k] * np.exp(1j * rows[0].numpy()), gn[:, k])
            assert _wrapdiff(cols[0, k].item(), ref) < 2e-3

    def test_full_quadrant(self):
        d = torch.ones(1, 1, 2, dtype=torch.complex128)
        for true in (-3.0, -2.0, 2.5, 3.1):
            g = d * np.exp(1j * true)
            assert abs(phase_step_1d(g, d).item() - true) < 1e-12

    def test_batch_and_shapes(self):
        g, d = _pair(1, shape=(0, 3, 4))
        assert phase_step_1d(g, d).shape == (0, 3)
        g, d = _pair(1, shape=(2, 3, 4))
        assert phase_step_2d(g, d).shape == (2, 3, 4)
        torch.testing.assert_close(phase_step_1d(g, d)[1:], phase_step_1d(g[1:], d[1:]))
