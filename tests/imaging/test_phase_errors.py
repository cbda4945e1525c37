from __future__ import annotations

import math

import pytest
import torch

from torchsar.errors import OptionError, ShapeError
from torchsar.imaging.phase_errors import (
    apply_phase_error,
    polynomial_phase_error,
    quadratic_phase_error,
    sinusoidal_phase_error,
    uniform_phase_error,
)
from torchsar.seeding import image_seed

ONE_D = [uniform_phase_error, quadratic_phase_error, polynomial_phase_error, sinusoidal_phase_error]


def separable_phase_error(*args, **kw):
    return uniform_phase_error(*args, separable=True, **kw)


def nonseparable_phase_error(*args, **kw):
    return uniform_phase_error(*args, **kw)


ALL = [*ONE_D, separable_phase_error, nonseparable_phase_error]


def _gen(seed=0):
    return torch.Generator().manual_seed(seed)


class TestGenerators:
    @pytest.mark.parametrize("fn", ONE_D)
    def test_1d_shape_range(self, fn):
        for b in (0, 1, 3):
            phi = fn(b, 16, amplitude=2.0, seed=0)
            assert phi.shape == (b, 16)
            assert (phi.abs() <= 2.0 + 1e-6).all()

    @pytest.mark.parametrize("fn", [separable_phase_error, nonseparable_phase_error])
    def test_2d_shape_range(self, fn):
        phi = fn(2, 8, 6, amplitude=1.0, seed=0)
        assert phi.shape == (2, 8, 6)
        bound = 2.0 if fn is separable_phase_error else 1.0
        assert (phi.abs() <= bound + 1e-6).all()

    def test_separable_is_rank_one_sum(self):
        phi = separable_phase_error(1, 8, 6, seed=0)[0]
        # phi_mk - phi_m0 - phi_0k + phi_00 == 0 for a sum of row and column terms
        resid = phi - phi[:, :1] - phi[:1, :] + phi[0, 0]
        assert resid.abs().max() < 1e-5

    def test_uniform_fills_range(self):
        phi = uniform_phase_error(1, 4000, seed=0)
        assert phi.min() < -0.99 * math.pi and phi.max() > 0.99 * math.pi

    def test_quadratic_is_quadratic(self):
        phi = quadratic_phase_error(2, 9, seed=0, dtype=torch.float64)
        t = torch.linspace(-1, 1, 9, dtype=torch.float64)
        coef = phi[:, -1:]
        torch.testing.assert_close(phi, coef * t**2)

    def test_seeded(self):
        a = nonseparable_phase_error(2, 4, 4, seed=5)
        b = nonseparable_phase_error(2, 4, 4, seed=5)
        assert torch.equal(a, b)
        assert not torch.equal(a, nonseparable_phase_error(2, 4, 4, seed=6))

    @pytest.mark.parametrize("fn", ALL)
    def test_item_independent_of_batch_size(self, fn):
        """Item ``i`` of a batch drawn with ``seed`` is the batch of one drawn with
        ``image_seed(seed, i)``; items differ from each other."""
        shape = (8,) if fn in ONE_D else (8, 5)
        big = fn(4, *shape, seed=9)
        for i in range(4):
            assert torch.equal(big[i : i + 1], fn(1, *shape, seed=image_seed(9, i)))
        assert torch.equal(big[:2], fn(2, *shape, seed=9))
        assert not torch.equal(big[0], big[1])

    def test_invalid(self):
        with pytest.raises(OptionError, match="amplitude"):
            uniform_phase_error(1, 4, amplitude=-1.0)
        with pytest.raises(OptionError, match="separable needs samples"):
            uniform_phase_error(1, 4, separable=True)
        with pytest.raises(OptionError, match="samples"):
            uniform_phase_error(1, 4, 0)
        with pytest.raises(OptionError, match="seed"):
            separable_phase_error(1, 4, 3, seed=-2)
        with pytest.raises(OptionError, match="seed"):
            quadratic_phase_error(1, 4, seed=2**63)
        with pytest.raises(OptionError, match="order"):
            polynomial_phase_error(1, 4, order=1)


class TestApply:
    def test_roundtrip_1d_and_2d(self):
        g = torch.randn(2, 4, 5, dtype=torch.complex128, generator=_gen())
        for phi in (
            torch.randn(2, 4, dtype=torch.float64),
            torch.randn(2, 4, 5, dtype=torch.float64),
        ):
            torch.testing.assert_close(apply_phase_error(apply_phase_error(g, phi), -phi), g)

    def test_1d_broadcasts_over_samples(self):
        g = torch.ones(1, 2, 3, dtype=torch.complex64)
        out = apply_phase_error(g, torch.tensor([[0.0, math.pi / 2]]))
        torch.testing.assert_close(out[0, 1], torch.full((3,), 1j, dtype=torch.complex64))

    def test_shape_error(self):
        with pytest.raises(ShapeError, match=r"\(B, M\)"):
            apply_phase_error(torch.ones(1, 2, 3, dtype=torch.complex64), torch.zeros(1, 3))
