"""The one spotlight world: both range models, the simulator on off-grid points, seeded noise."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.reference.imaging import exact_phase_history
from torchsar.errors import OptionError
from torchsar.imaging import point_scene, speckled_scene
from torchsar.motion import SpotlightParams
from torchsar.sar import SpotlightGeometry, Track, add_noise, simulate_phase_history
from torchsar.simulate import image_seed


def _track_geometry(scene_range: float = 1e4) -> SpotlightGeometry:
    track = Track(platform_speed=200.0, scene_range=scene_range, prf=200.0)
    return SpotlightGeometry(10e9, 150e6, 0.02, pulses=9, samples=6, track=track)


class TestRangeModels:
    def test_far_field_limit_of_the_track_is_the_plane_wave_projection(self):
        geo = _track_geometry(scene_range=1e9)
        points = torch.tensor([[3.0, -4.0], [-7.5, 2.0]], dtype=torch.float64)
        th = geo.angles()
        plane = points[:, :1] * th.cos() + points[:, 1:] * th.sin()
        torch.testing.assert_close(geo.differential_ranges(points), plane, atol=1e-6, rtol=0)

    def test_sampling_is_symmetric_on_a_track_and_dft_centred_on_a_raster(self):
        geo = _track_geometry()
        assert float(geo.frequencies().mean()) == pytest.approx(geo.center_frequency, rel=1e-15)
        assert float(geo.pulse_times().sum()) == pytest.approx(0.0, abs=1e-15)
        raster = SpotlightGeometry.for_image((6, 6))
        assert float(raster.frequencies()[3]) == raster.center_frequency
        assert float(raster.angles()[3]) == 0.0

    def test_the_raster_has_no_slow_time(self):
        geo = SpotlightGeometry.for_image((4, 4))
        with pytest.raises(OptionError, match="track"):
            _ = geo.aperture_time
        pos = torch.zeros(1, 1, 2)
        with pytest.raises(OptionError, match="moving scatterers need a track"):
            simulate_phase_history(pos, geo, velocities=torch.ones(1, 1, 2))
        zero = simulate_phase_history(pos, geo, velocities=torch.zeros(1, 1, 2))
        torch.testing.assert_close(zero, simulate_phase_history(pos, geo))

    def test_motion_params_need_a_track(self):
        with pytest.raises(OptionError, match="with a track"):
            SpotlightParams(SpotlightGeometry.for_image((4, 4)))


def test_off_grid_points_match_the_triple_loop():
    geo = SpotlightGeometry.for_image((5, 4), pixel=0.7, center_frequency=3e9)
    gen = torch.Generator().manual_seed(4)
    pos = (torch.rand(1, 3, 2, generator=gen, dtype=torch.float64) - 0.5) * 4
    amp = torch.randn(1, 3, generator=gen, dtype=torch.complex128)
    g = simulate_phase_history(pos, geo, amplitudes=amp)
    ref = exact_phase_history(
        amp[0].numpy(),
        pos[0, :, 0].numpy(),
        pos[0, :, 1].numpy(),
        geo.wavenumbers().numpy(),
        geo.angles().numpy(),
    )
    np.testing.assert_allclose(g[0].numpy(), ref, atol=1e-10)


class TestSeeds:
    def test_noise_of_an_item_does_not_depend_on_the_batch(self):
        g = torch.zeros(3, 8, 8, dtype=torch.complex128)
        whole = add_noise(g, std=1.0, seed=5)
        for b in range(3):
            alone = add_noise(g[b : b + 1], std=1.0, seed=image_seed(5, b))
            torch.testing.assert_close(whole[b : b + 1], alone, atol=0, rtol=0)
        assert not torch.equal(whole[0], whole[1])

    def test_noise_level(self):
        g = torch.ones(2, 64, 64, dtype=torch.complex128)
        n = add_noise(g, std=0.5, seed=0) - g
        assert float(n.abs().square().mean()) == pytest.approx(0.25, rel=0.05)
        with pytest.raises(OptionError, match="exactly one"):
            add_noise(g, std=0.5, snr_db=10.0)
        with pytest.raises(OptionError, match="exactly one"):
            add_noise(g)

    @pytest.mark.parametrize("make", [point_scene, speckled_scene])
    def test_scene_of_an_item_does_not_depend_on_the_batch(self, make):
        f, m = make(3, size=(16, 16), seed=9)
        for b in range(3):
            fb, mb = make(1, size=(16, 16), seed=image_seed(9, b))
            torch.testing.assert_close(f[b : b + 1], fb, atol=0, rtol=0)
            assert torch.equal(m[b : b + 1], mb)


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    split=st.integers(1, 4),
    tracked=st.booleans(),
)
def test_scatterers_superpose(seed, split, tracked):
    """The data of a scene are the sum of the data of any split of its scatterers."""
    geo = _track_geometry() if tracked else SpotlightGeometry.for_image((7, 6), pixel=0.5)
    gen = torch.Generator().manual_seed(seed)
    pos = (torch.rand(1, 5, 2, generator=gen, dtype=torch.float64) - 0.5) * 20
    vel = torch.randn(1, 5, 2, generator=gen, dtype=torch.float64) if tracked else None
    amp = torch.randn(1, 5, generator=gen, dtype=torch.complex128)

    def part(sl: slice) -> torch.Tensor:
        v = None if vel is None else vel[:, sl]
        return simulate_phase_history(pos[:, sl], geo, velocities=v, amplitudes=amp[:, sl])

    whole = part(slice(None))
    torch.testing.assert_close(whole, part(slice(0, split)) + part(slice(split, None)))
