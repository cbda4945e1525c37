from __future__ import annotations

import math

import pytest
import torch

from torchsar.errors import OptionError
from torchsar.imaging import (
    AutofocusResult,
    FourierOperator,
    apply_phase_error,
    quadratic_phase_error,
    sparse_autofocus,
    uniform_phase_error,
)
from torchsar.imaging.fidelity import magnitude_correlation, phase_rmse
from torchsar.seeding import image_seed


class TestAcceptance:
    """Default lam recovers exact-model sparse scenes (no inverse crime) to corr >= 0.98."""

    def test_1d_uniform_pi(self, sparse_data):
        f, _, g = sparse_data
        phi = uniform_phase_error(4, 32, amplitude=math.pi, seed=1)
        out = sparse_autofocus(apply_phase_error(g, phi), error="1d")
        assert out.phase.shape == (4, 32)
        assert (magnitude_correlation(out.image, f) >= 0.98).all()
        assert (phase_rmse(out.phase, phi) < 0.1).all()

    def test_1d_quadratic(self, sparse_data):
        f, _, g = sparse_data
        phi = quadratic_phase_error(4, 32, amplitude=4 * math.pi, seed=2)
        out = sparse_autofocus(apply_phase_error(g, phi), error="1d")
        assert (magnitude_correlation(out.image, f) >= 0.98).all()

    def test_2d_separable(self, sparse_data):
        f, _, g = sparse_data
        phi = uniform_phase_error(4, 32, 32, separable=True, amplitude=0.75 * math.pi, seed=3)
        out = sparse_autofocus(apply_phase_error(g, phi), error="2d-separable")
        assert out.phase.shape == (4, 32, 32)
        assert (magnitude_correlation(out.image, f) >= 0.98).all()
        assert (phase_rmse(out.phase, phi) < 0.1).all()

    def test_2d_nonseparable(self, sparse_data):
        f, _, g = sparse_data
        phi = uniform_phase_error(4, 32, 32, amplitude=0.75 * math.pi, seed=4)
        out = sparse_autofocus(apply_phase_error(g, phi), error="2d")
        assert (magnitude_correlation(out.image, f, flip=True) >= 0.98).all()

    def test_uncorrected_is_worse(self, sparse_data):
        f, _, g = sparse_data
        phi = uniform_phase_error(4, 32, amplitude=math.pi, seed=1)
        conv = torch.fft.ifft2(apply_phase_error(g, phi)).unsqueeze(1)
        assert (magnitude_correlation(conv, f) < 0.7).all()


class TestSolver:
    def test_cost_monotone_without_warmup(self, sparse_data):
        _, _, g = sparse_data
        phi = uniform_phase_error(4, 32, seed=5)
        out = sparse_autofocus(apply_phase_error(g, phi), warmup=0, max_iter=30)
        steps = out.history[:, 1:] - out.history[:, :-1]
        assert (steps <= 1e-4 * out.history[:, :1]).all()

    def test_per_item_stopping_and_batch_invariance(self, sparse_data):
        _, _, g = sparse_data
        phi = uniform_phase_error(4, 32, seed=6)
        gc = apply_phase_error(g, phi)
        both = sparse_autofocus(gc[:2])
        one = sparse_autofocus(gc[1:2])
        assert both.iterations[1] == one.iterations[0]
        torch.testing.assert_close(both.image[1:], one.image, atol=1e-4, rtol=1e-3)
        torch.testing.assert_close(both.lam[1:], one.lam)
        assert isinstance(both, AutofocusResult)

    def test_empty_batch(self):
        out = sparse_autofocus(torch.zeros(0, 8, 8, dtype=torch.complex64), error="2d")
        assert out.image.shape == (0, 1, 8, 8) and out.phase.shape == (0, 8, 8)

    def test_restarts_never_worse(self, sparse_data):
        _, _, g = sparse_data
        phi = uniform_phase_error(2, 32, 32, amplitude=math.pi, seed=7)
        gc = apply_phase_error(g[:2], phi)
        base = sparse_autofocus(gc, error="2d", max_iter=20)
        more = sparse_autofocus(gc, error="2d", max_iter=20, restarts=1, seed=8)
        assert (more.cost <= base.cost + 1e-6).all()

    def test_restart_seeds_are_per_item(self, sparse_data):
        """Item ``i``'s random starts come from ``image_seed(seed, i)``: batch size is irrelevant."""
        _, _, g = sparse_data
        gc = apply_phase_error(
            g[:2], uniform_phase_error(2, 32, 32, amplitude=0.75 * math.pi, seed=7)
        )
        opts = {"error": "2d", "max_iter": 5, "restarts": 2}
        both = sparse_autofocus(gc, seed=3, **opts)
        one = sparse_autofocus(gc[1:], seed=image_seed(3, 1), **opts)
        torch.testing.assert_close(both.image[1:], one.image, atol=1e-4, rtol=1e-3)
        torch.testing.assert_close(both.cost[1:], one.cost, atol=1e-4, rtol=1e-4)
        again = sparse_autofocus(gc, seed=3, **opts)
        assert torch.equal(both.image, again.image)
        empty = sparse_autofocus(gc[:0], seed=3, **opts)
        assert empty.image.shape == (0, 1, 32, 32)
        with pytest.raises(OptionError, match="seed"):
            sparse_autofocus(gc, restarts=1, seed=-1)

    def test_missing_pulses(self, sparse_data):
        f, _, g = sparse_data
        mask = torch.ones(32, 32, dtype=torch.bool)
        mask[::5] = False  # 20 % of the pulses missing
        phi = uniform_phase_error(2, 32, seed=9)
        op = FourierOperator((32, 32), mask=mask)
        gc = apply_phase_error(g[:2], phi) * mask
        out = sparse_autofocus(gc, operator=op, max_iter=30, cg_iterations=5)
        assert (magnitude_correlation(out.image, f[:2]) >= 0.95).all()

    def test_given_lam_and_float64(self, sparse_data):
        _, _, g = sparse_data
        out = sparse_autofocus(g[:1].to(torch.complex128), lam=0.1, max_iter=3)
        assert out.image.dtype == torch.complex128 and out.phase.dtype == torch.float64
        assert out.lam.tolist() == [0.1]

    def test_exceptions(self, sparse_data):
        _, _, g = sparse_data
        with pytest.raises(OptionError, match="error must be one of '1d', '2d-separable', '2d'"):
            sparse_autofocus(g, error="3d")
        with pytest.raises(OptionError, match="restarts"):
            sparse_autofocus(g, restarts=-1)
        with pytest.raises(OptionError, match="max_iter"):
            sparse_autofocus(g, max_iter=1.5)


class TestPhaseRetrieval:
    """Fully random 2-D errors in [-pi, pi]: hard threshold + restarts (cost-selected)."""

    def test_keep_with_restarts_recovers_sparse_scene(self):
        from torchsar.imaging import point_scene
        from torchsar.sar import SpotlightGeometry, add_noise, phase_history

        f, _ = point_scene(2, size=(16, 16), points=6, seed=11)
        g = add_noise(phase_history(f, SpotlightGeometry.for_image((16, 16))), snr_db=30.0, seed=11)
        phi = uniform_phase_error(2, 16, 16, amplitude=math.pi, seed=13)
        gc = apply_phase_error(g, phi)
        out = sparse_autofocus(
            gc, error="2d", keep=9, restarts=5, warmup=0, max_iter=100, tol=1e-5, seed=12
        )
        corr = magnitude_correlation(out.image, f, flip=True)
        assert (corr >= 0.98).all()
        assert ((out.image.abs() > 0).flatten(1).sum(1) <= 9).all()
