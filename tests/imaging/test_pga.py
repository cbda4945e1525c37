from __future__ import annotations

import math

import pytest
import torch

from torchsar.errors import InputTypeError, OptionError
from torchsar.imaging import (
    apply_phase_error,
    fft2c,
    ifft2c,
    polynomial_phase_error,
    quadratic_phase_error,
)
from torchsar.imaging.fidelity import magnitude_correlation, phase_rmse
from torchsar.imaging.min_entropy import min_entropy_autofocus
from torchsar.imaging.pga import pga


def _point_targets(b=2, n=32):
    f = torch.zeros(b, 1, n, n, dtype=torch.complex128)
    f[:, 0, 5, 9] = 1.0
    f[:, 0, 20, 3] = 0.7j
    f[:, 0, 12, 25] = -0.8
    return f


def _blurred(f, phi):
    return ifft2c(apply_phase_error(fft2c(f[:, 0]), phi)).unsqueeze(1)


class TestPGA:
    def test_recovers_smooth_error(self):
        f = _point_targets()
        phi = quadratic_phase_error(
            2,
            32,
            amplitude=2 * math.pi,
            seed=0,
            dtype=torch.float64,
        )
        out = pga(_blurred(f, phi))
        assert (phase_rmse(out.phase, phi) < 0.1).all()
        assert (magnitude_correlation(out.image, f) > 0.99).all()
        assert (magnitude_correlation(_blurred(f, phi), f) < 0.9).all()

    def test_no_error_is_fixed_point(self):
        f = _point_targets(1)
        out = pga(ifft2c(fft2c(f[:, 0])).unsqueeze(1))
        assert out.phase.abs().max() < 1e-6
        assert out.iterations.tolist() == [1]

    def test_batch(self):
        f = _point_targets(2)
        phi = 2 * torch.linspace(-1, 1, 32, dtype=torch.float64)[None].square().expand(2, 32)
        both = pga(_blurred(f, phi))
        one = pga(_blurred(f[1:], phi[1:]))
        torch.testing.assert_close(both.phase[1:], one.phase)
        assert pga(torch.zeros(0, 1, 8, 8, dtype=torch.complex64)).image.shape == (0, 1, 8, 8)

    def test_exceptions(self):
        with pytest.raises(InputTypeError, match="complex"):
            pga(torch.ones(1, 1, 8, 8))
        with pytest.raises(OptionError, match="window_db"):
            pga(torch.ones(1, 1, 8, 8, dtype=torch.complex64), window_db=3.0)


class TestMinEntropy:
    def test_recovers_error(self):
        f = _point_targets()
        phi = polynomial_phase_error(
            2,
            32,
            order=3,
            amplitude=2 * math.pi,
            seed=1,
            dtype=torch.float64,
        )
        g = apply_phase_error(fft2c(f[:, 0]), phi)
        out = min_entropy_autofocus(g)
        assert (magnitude_correlation(out.image, f) > 0.99).all()
        assert out.phase.shape == (2, 32) and out.entropy.shape == (2,)

    def test_empty(self):
        out = min_entropy_autofocus(torch.zeros(0, 4, 4, dtype=torch.complex64))
        assert out.image.shape == (0, 1, 4, 4)
