from __future__ import annotations

import pytest
import torch

from torchsar.motion import (
    first_order_offsets,
    folded_speed,
    planar_image_positions,
    scene_positions,
    subpatch_centers,
)

POS = torch.tensor([[-20.0, -15.0], [10.0, 5.0], [25.0, -20.0], [0.0, 0.0]], dtype=torch.float64)


def _offsets(params, v):
    c = subpatch_centers(params)
    vel = torch.zeros_like(POS)
    vel[3] = torch.tensor(v, dtype=torch.float64)
    moving = planar_image_positions(POS, params, c, velocities=vel)
    still = planar_image_positions(POS, params, c)
    return moving[3] - still[3], first_order_offsets(POS, vel, params, c)[3], c


class TestPlanarTheory:
    def test_point_at_centre_has_no_distortion(self, small):
        c = torch.tensor([[30.0, -40.0]], dtype=torch.float64)
        got = planar_image_positions(torch.tensor([[31.0, -39.5]]), small, c)
        torch.testing.assert_close(
            got[0, 0], torch.tensor([1.0, 0.5], dtype=torch.float64), atol=1e-3, rtol=0
        )

    def test_distortion_grows_quadratically(self, small):
        c = torch.zeros(1, 2, dtype=torch.float64)
        d = [
            planar_image_positions(torch.tensor([[0.0, x]]), small, c)[0, 0, 0]
            for x in (20.0, 40.0)
        ]
        # range distortion of a cross-range offset x is ~ x^2 / (2 R0)
        assert float(d[0]) == pytest.approx(20.0**2 / 2e4, rel=0.05)
        assert float(d[1]) == pytest.approx(40.0**2 / 2e4, rel=0.05)

    @pytest.mark.parametrize("v", [0.2, 0.39, -0.45])
    def test_first_order_radial_motion(self, small, v):
        got, first, _ = _offsets(small, (v, 0.0))
        torch.testing.assert_close(got, first, atol=0.01 * abs(v) + 1e-3, rtol=0)

    def test_azimuth_motion_is_the_same_in_every_subpatch(self, small):
        got, first, _ = _offsets(small, (0.0, 5.0))
        spread = (got - got.mean(0)).abs().max()
        assert float(spread) < 0.03  # vs a radial mover of the same speed: ~2.5 m
        torch.testing.assert_close(got, first, atol=0.05, rtol=0)

    def test_aliased_radial_motion_folds(self, small):
        v = 2.34
        got, _, c = _offsets(small, (v, 0.0))
        assert folded_speed(v, small) == pytest.approx(v - small.geometry.blind_speed)
        # the window shows replica k of the aliased mover, which behaves as speed v + k v_b
        x = POS[3, 1] - c[:, 1] - (small.track.scene_range + c[:, 0]) * v / 200.0
        k = torch.round(x / small.geometry.unambiguous_azimuth)
        v_k = v + k * small.geometry.blind_speed
        for p, q in ((0, 2), (1, 3)):  # same azimuth centre, 100 m apart in range
            diff = got[q, 1] - got[p, 1]
            assert float(v_k[p]) == pytest.approx(float(v_k[q]))
            assert float(diff) == pytest.approx(-float(v_k[p]) * 100.0 / 200.0, abs=0.02)
        assert set(k.tolist()) == {0.0, -1.0}  # two replicas appear, depending on the centre

    def test_scene_positions_inverts_the_stationary_model(self, small):
        c = subpatch_centers(small)
        q = planar_image_positions(POS, small, c)
        back = scene_positions(q, small, c)
        torch.testing.assert_close(back, POS[:, None].expand_as(back), atol=1e-4, rtol=0)
