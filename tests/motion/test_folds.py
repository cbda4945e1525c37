"""Doppler folds: the residual range walk of a folded radial mover, its undoing, its theory."""

from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.motion.conftest import make_params
from tests.motion.test_looks import _peak, _position
from torchsar.errors import InputTypeError, ShapeError
from torchsar.motion import (
    doppler_fold,
    look_images,
    look_plan,
    planar_image_positions,
    polar_format,
    radial_speed_interval,
    unwalk,
    walk_rate,
)
from torchsar.sar import simulate_phase_history

# The table: target at (20, 10) m, radial speeds not folded, folded once and twice.
RADIAL = [0.0, 0.6, 1.1, 1.9, 2.6, 4.4, 7.1, -4.4]


@pytest.fixture(scope="module")
def table1():
    """Table 1 aperture (500 pulses, 2.5 s), 256 x 512 images (0.70 m x 0.29 m pixels)."""
    return make_params(image_size=(256, 512))


@pytest.fixture(scope="module")
def radial(table1):
    pos = torch.tensor([[[20.0, 10.0]]], dtype=torch.float64).expand(len(RADIAL), 1, 2)
    vel = torch.zeros(len(RADIAL), 1, 2, dtype=torch.float64)
    vel[:, 0, 0] = torch.tensor(RADIAL, dtype=torch.float64)
    g = simulate_phase_history(pos.contiguous(), table1.geometry, velocities=vel)
    return pos, vel, g


def _first_order_fold(params, y: float, x: float, v_r: float) -> int:
    """round((x - R v_r / V) / P_R), written out."""
    r = params.track.scene_range + y
    period = params.geometry.wavelength * params.track.prf * r / (2 * params.track.platform_speed)
    return math.floor((x - r * v_r / params.track.platform_speed) / period + 0.5)


class TestWalk:
    def test_looks_walk_k_lambda_prf_dt_over_2_in_range(self, table1, radial):
        """Measured range displacement between two looks vs -k lambda PRF dt / 2."""
        g = radial[2]
        x = look_images(g, table1)
        plan = look_plan(table1)
        dt = float(plan.time[1] - plan.time[0])
        spacing = torch.tensor(table1.pixel_spacing, dtype=torch.float64)
        for b, v_r in enumerate(RADIAL):
            k = _first_order_fold(table1, 20.0, 10.0, v_r)
            d = _position(x[b, 1], x[b, 0], _peak(x[b, 0])) * spacing
            assert abs(float(d[0]) - walk_rate(k, table1) * dt) < 0.1, (v_r, k, d)
            assert abs(float(d[1])) < 0.1  # no azimuth displacement

    def test_walk_rate_is_three_metres_per_second_per_fold(self, table1):
        assert walk_rate(2, table1) == pytest.approx(-2 * 0.03 * 200 / 2, rel=1e-3)

    def test_unwalk_compacts_the_folded_mover_only_at_its_fold(self, table1, radial):
        _, _, g = radial
        img = polar_format(g, table1)
        folds = torch.arange(-3, 4)
        peaks = unwalk(img, table1, folds).abs().flatten(-2).amax(-1)  # (B, 7)
        for b, v_r in enumerate(RADIAL):
            k = _first_order_fold(table1, 20.0, 10.0, v_r)
            assert int(folds[peaks[b].argmax()]) == k
            assert float(peaks[b].max()) > 0.85  # compact again
        assert peaks[3, 3] < 0.6 and peaks[6, 3] < 0.35  # folded once / twice: smeared

    def test_unwalk_compacts_where_the_planar_model_shows_the_target(self, table1, radial):
        pos, vel, g = radial
        img = polar_format(g[3:4], table1)  # fold -1
        for t in (0.0, 0.5):
            still = unwalk(img, table1, torch.tensor([0]), center_time=t)[0, 0]
            assert torch.allclose(still, img[0], atol=1e-5)  # fold 0 is the identity
        fixed = unwalk(img, table1, torch.tensor([-1]))[0, 0]
        shown = planar_image_positions(pos[3], table1, torch.zeros(1, 2), velocities=vel[3])
        expected = shown[0, 0] / torch.tensor(table1.pixel_spacing) + torch.tensor([128, 256])
        assert (_peak(fixed) - expected).abs().max() <= 2.0  # 0.6 m: the model's own error

    def test_bad_input(self, table1):
        with pytest.raises(InputTypeError):
            unwalk(torch.zeros(4, 4), table1, torch.tensor([1]))
        with pytest.raises(ShapeError):
            unwalk(torch.zeros(4, 4, dtype=torch.complex64), table1, torch.tensor(1))


class TestFoldTheory:
    @settings(max_examples=40, deadline=None)
    @given(
        y=st.floats(-80, 80),
        x=st.floats(-70, 70),
        v_r=st.floats(-9, 9),
    )
    def test_fold_matches_first_order_and_planar_model(self, y, x, v_r):
        p = make_params()
        pos = torch.tensor([[y, x]], dtype=torch.float64)
        vel = torch.tensor([[v_r, 0.0]], dtype=torch.float64)
        k = int(doppler_fold(pos, p, velocities=vel)[0])
        assert k == _first_order_fold(p, y, x, v_r)
        # the planar model shows the target k sampled extents from its unfolded position
        shown = planar_image_positions(pos, p, torch.zeros(1, 2), velocities=vel)[0, 0, 1]
        apparent = x - (p.track.scene_range + y) * v_r / p.track.platform_speed
        unfolded = apparent * p.track.scene_range / (p.track.scene_range + y)
        period = p.geometry.unambiguous_azimuth
        if abs(abs(unfolded / period - k) - 0.5) > 0.01:  # away from a fold boundary
            assert float(unfolded - shown) == pytest.approx(k * period, abs=0.5)

    def test_stationary_scatterer_beyond_the_sampled_extent_folds(self):
        p = make_params()
        pos = torch.tensor([[0.0, 74.0], [0.0, 76.0], [0.0, -76.0]])
        assert doppler_fold(pos, p).tolist() == [0, 1, -1]

    @settings(max_examples=40, deadline=None)
    @given(y=st.floats(-80, 80), x=st.floats(-100, 100), v_r=st.floats(-12, 12))
    def test_radial_interval_holds_the_true_speed(self, y, x, v_r):
        """Any scatterer of the scene: its radial speed is in the interval of its fold."""
        p = make_params()
        pos = torch.tensor([[y, x]], dtype=torch.float64)
        vel = torch.tensor([[v_r, 0.0]], dtype=torch.float64)
        k = doppler_fold(pos, p, velocities=vel)
        shown = planar_image_positions(pos, p, torch.zeros(1, 2), velocities=vel)[:, 0]
        lo, hi = radial_speed_interval(k, shown, p)[0].tolist()
        assert lo - 0.02 <= v_r <= hi + 0.02
        width = p.track.platform_speed * p.scene_extent[1] / (p.track.scene_range + y)
        assert hi - lo == pytest.approx(width, rel=0.01)
