from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
import torch

from tests.reference.imaging import exact_phase_history
from torchsar.errors import InputTypeError, OptionError, ShapeError
from torchsar.imaging.fourier import fft2c, ifft2c
from torchsar.imaging.scenes import point_scene
from torchsar.sar import (
    SPEED_OF_LIGHT,
    SpotlightGeometry,
    Track,
    add_noise,
    image_noise_std,
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


class TestRaggedScenes:
    """Scenes of unequal sizes in one call: each scene as if simulated alone."""

    @staticmethod
    def _geometry() -> SpotlightGeometry:
        track = Track(platform_speed=200.0, scene_range=1e4, prf=200.0)
        return SpotlightGeometry(10e9, 150e6, 0.02, pulses=9, samples=6, track=track)

    def test_each_scene_equals_its_own_call(self):
        geo = self._geometry()
        gen = torch.Generator().manual_seed(3)
        counts = [2, 0, 5]
        pos = [(torch.rand(n, 2, generator=gen, dtype=torch.float64) - 0.5) * 40 for n in counts]
        vel = [torch.randn(n, 2, generator=gen, dtype=torch.float64) for n in counts]
        amp = [torch.randn(n, generator=gen, dtype=torch.complex128) for n in counts]
        g = simulate_phase_history(pos, geo, velocities=vel, amplitudes=amp)
        assert g.shape == (3, 9, 6) and g.dtype == torch.complex128
        for b in range(3):
            alone = simulate_phase_history(
                pos[b][None], geo, velocities=vel[b][None], amplitudes=amp[b][None]
            )
            torch.testing.assert_close(g[b : b + 1], alone, atol=1e-12, rtol=0)
        assert torch.equal(g[1], torch.zeros_like(g[1]))  # an empty scene has no echo

    def test_defaults_and_empty_batch(self):
        geo = self._geometry()
        pos = [torch.zeros(1, 2), torch.zeros(3, 2)]
        g = simulate_phase_history(pos, geo)
        torch.testing.assert_close(g[:, 4, 3].real, torch.tensor([1.0, 3.0]))
        assert simulate_phase_history([], geo).shape == (0, 9, 6)

    def test_errors_name_the_argument(self):
        geo = self._geometry()
        pos = [torch.zeros(1, 2), torch.zeros(3, 2)]
        with pytest.raises(InputTypeError, match="velocities"):
            simulate_phase_history(pos, geo, velocities=[torch.zeros(1, 2)])
        with pytest.raises(InputTypeError, match="amplitudes"):
            simulate_phase_history(pos, geo, amplitudes=torch.ones(2, 3))
        with pytest.raises(ShapeError, match=r"velocities\[1\]"):
            simulate_phase_history(pos, geo, velocities=[torch.zeros(1, 2), torch.zeros(2, 2)])
        with pytest.raises(ShapeError, match=r"positions\[0\]"):
            simulate_phase_history([torch.zeros(1, 3)], geo)


class TestImageNoise:
    def test_taper_gain_is_the_closed_form(self):
        geo = SpotlightGeometry.for_image((64, 32))
        hann = math.sqrt(2 * 63 / 3) * math.sqrt(2 * 31 / 3) * 10 ** (-20 / 20)
        assert image_noise_std(geo, 20.0) == pytest.approx(hann, rel=1e-12)
        assert image_noise_std(geo, 20.0, window="none") == pytest.approx(
            math.sqrt(64 * 32) / 10, rel=1e-12
        )

    @pytest.mark.parametrize("window", ["hann", "none"])
    def test_measured_image_snr(self, window):
        """A unit point formed by polar formatting peaks ``snr_db`` above the image noise."""
        from torchsar.motion import SpotlightParams, polar_format

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            p = SpotlightParams.from_system(azimuth_resolution=1.0, image_size=(128, 128))
        std = image_noise_std(p.geometry, 25.0, window=window)
        zero = torch.zeros(4, p.geometry.pulses, p.geometry.samples, dtype=torch.complex128)
        noise = polar_format(add_noise(zero, std=std, seed=2), p, window=window)
        point = simulate_phase_history(torch.zeros(1, 1, 2, dtype=torch.float64), p.geometry)
        peak = polar_format(point, p, window=window).abs().square().max()
        snr = 10 * math.log10(float(peak / noise.abs().square().mean()))
        assert snr == pytest.approx(25.0, abs=0.15)

    def test_bad_options(self):
        geo = SpotlightGeometry.for_image((8, 8))
        with pytest.raises(OptionError, match="snr_db"):
            image_noise_std(geo, float("nan"))
        with pytest.raises(OptionError, match="window"):
            image_noise_std(geo, 10.0, window="kaiser")
