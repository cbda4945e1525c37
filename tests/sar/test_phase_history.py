from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from tests.reference.imaging import exact_phase_history
from torchsar._checks import OptionError, ShapeError
from torchsar.imaging.fourier import fft2c, ifft2c
from torchsar.imaging.scenes import point_scene
from torchsar.sar import (
    SPEED_OF_LIGHT,
    SpotlightGeometry,
    add_noise,
    phase_history,
    simulate_phase_history,
)


class TestGeometry:
    def test_pixel_spacing(self):
        geo = SpotlightGeometry.for_image((16, 8), pixel=0.5, center_frequency=9e9)
        assert geo.range_resolution == pytest.approx(0.5)
        assert geo.cross_range_resolution == pytest.approx(0.5)
        assert geo.wavenumbers().shape == (8,)
        assert geo.angles().shape == (16,)
        assert geo.angles()[8] == 0

    def test_centre_wavenumber(self):
        geo = SpotlightGeometry.for_image((4, 4), center_frequency=10e9)
        u = geo.wavenumbers()[2].item()
        assert u == pytest.approx(4 * math.pi * 10e9 / SPEED_OF_LIGHT)

    def test_invalid(self):
        with pytest.raises(OptionError, match="bandwidth"):
            SpotlightGeometry(1e9, 3e9, 0.01, 4, 4)
        with pytest.raises(OptionError, match="pulses"):
            SpotlightGeometry(1e9, 1e8, 0.01, 0, 4)


class TestPhaseHistory:
    def test_matches_triple_loop(self):
        geo = SpotlightGeometry.for_image((5, 4), pixel=1.0, center_frequency=3e9)
        f, _ = point_scene(1, size=(5, 4), points=3, seed=1, dtype=torch.complex128)
        g = phase_history(f, geo)
        y, x = geo.pixel_positions((5, 4))
        yy, xx = np.meshgrid(y.numpy(), x.numpy(), indexing="ij")
        ref = exact_phase_history(
            f[0, 0].numpy().ravel(),
            xx.ravel(),
            yy.ravel(),
            geo.wavenumbers().numpy(),
            geo.angles().numpy(),
        ) / math.sqrt(20)
        np.testing.assert_allclose(g[0].numpy(), ref, atol=1e-10)

    def test_rvp_path_equals_separable_without_chirp(self):
        geo = SpotlightGeometry.for_image((6, 6))
        f, _ = point_scene(2, size=(6, 6), points=4, seed=2, dtype=torch.complex128)
        torch.testing.assert_close(phase_history(f, geo, rvp=True), phase_history(f, geo))

    def test_rvp_phase(self):
        alpha = 1e17  # rad/s^2, i.e. a sweep rate of alpha / pi Hz/s
        geo = SpotlightGeometry.for_image((4, 4), chirp_rate=alpha / math.pi)
        pos = torch.tensor([[[3.0, 0.0]]], dtype=torch.float64)
        a = torch.ones(1, 1, dtype=torch.complex128)
        ratio = simulate_phase_history(pos, geo, amplitudes=a, rvp=True) / simulate_phase_history(
            pos, geo, amplitudes=a
        )
        u = 3.0 * geo.angles().cos()
        expected = torch.polar(
            torch.ones(4, dtype=torch.float64), 4 * alpha * u**2 / SPEED_OF_LIGHT**2
        )
        torch.testing.assert_close(ratio[0], expected[:, None].expand(4, 4))

    def test_narrow_angle_close_to_fft(self):
        geo = SpotlightGeometry.for_image((32, 32), pixel=1.0)
        f, _ = point_scene(2, size=(32, 32), points=10, seed=3)
        img = ifft2c(phase_history(f, geo)).abs()
        corr = torch.nn.functional.cosine_similarity(img.flatten(1), f.abs().flatten(1))
        assert (corr > 0.98).all()
        # but not identical to the operator (no inverse crime)
        assert (phase_history(f, geo) - fft2c(f[:, 0])).abs().max() > 1e-3

    def test_batch_sizes(self):
        geo = SpotlightGeometry.for_image((4, 4))
        for b in (0, 1, 2):
            assert phase_history(torch.zeros(b, 1, 4, 4, dtype=torch.complex64), geo).shape == (
                b,
                4,
                4,
            )

    def test_dtype(self):
        geo = SpotlightGeometry.for_image((4, 4))
        assert phase_history(torch.zeros(1, 1, 4, 4, dtype=torch.complex128), geo).dtype == (
            torch.complex128
        )

    def test_errors(self):
        geo = SpotlightGeometry.for_image((4, 4))
        with pytest.raises(ShapeError, match="one channel"):
            phase_history(torch.zeros(1, 2, 4, 4, dtype=torch.complex64), geo)
        with pytest.raises(ShapeError, match=r"\(B, N, 2\)"):
            simulate_phase_history(torch.zeros(1, 3), geo, amplitudes=torch.zeros(1, 3))


class TestNoise:
    def test_snr(self):
        g = torch.ones(2, 64, 64, dtype=torch.complex128)
        noise = add_noise(g, snr_db=10.0, seed=0) - g
        snr = 10 * torch.log10(1 / noise.abs().square().mean(dim=(1, 2)))
        torch.testing.assert_close(
            snr, torch.full((2,), 10.0, dtype=torch.float64), atol=0.2, rtol=0
        )

    def test_option(self):
        with pytest.raises(OptionError, match="snr_db"):
            add_noise(torch.ones(1, 2, 2, dtype=torch.complex64), snr_db="x")
