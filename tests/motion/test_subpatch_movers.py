"""End to end: simulated scenes through subpatch images to the mover decision (reduced size)."""

from __future__ import annotations

import torch

from torchsar.motion import subpatch_movers
from torchsar.sar import add_noise, simulate_phase_history

STILL = [[-25.0, -20.0], [20.0, -8.0], [-5.0, 6.0]]


def _scene(params, last, velocity=(0.0, 0.0), seed=0, noise=0.05):
    pos = torch.tensor([[*STILL, last]], dtype=torch.float64)
    vel = torch.zeros_like(pos)
    vel[0, 3] = torch.tensor(velocity, dtype=torch.float64)
    g = simulate_phase_history(pos, params.geometry, velocities=vel)
    g = add_noise(g, std=noise, seed=seed)
    return subpatch_movers(g.to(torch.complex64), params)


def _track_of(result, params, expected):
    """Index of the track whose reference-image position is nearest ``expected`` (m)."""
    pos0 = result.tracks.position[0, :, 0]
    return int((pos0 - torch.tensor(expected, dtype=torch.float64)).norm(dim=-1).argmin())


class TestFindMovers:
    def test_stationary_scene_has_no_movers(self, small):
        r = _scene(small, [10.0, 20.0])
        assert r.tracks.valid[0].all() and r.tracks.valid.shape[1] == 4
        assert not r.decision.mover.any()
        assert r.tracks.corrected[0].abs().nan_to_num().max() < 0.05

    def test_aliased_mover_is_flagged_like_its_stationary_lookalike(self, small):
        # 2.34 m/s: apparent azimuth 20 - 117 = -97 m, outside the zone shared by the four
        # 150 m subpatch windows, so the subpatch images show different replicas ...
        v, y, x = 2.34, 10.0, 20.0
        r = _scene(small, [y, x], (v, 0.0))
        assert r.decision.mover[0].sum() == 1
        # reference image centre (-50, -50): range + v x_c / V, azimuth - v R_c / V
        mover = _track_of(r, small, [60.0 - 0.585, 70.0 - 116.4])
        assert r.decision.mover[0, mover]
        assert float(r.decision.residual[0, mover].norm(dim=-1).max()) > 0.2
        # ... and a stationary target at that apparent position is flagged just the same
        apparent = [y + v * x / 200.0, x - v * (small.track.scene_range + y) / 200.0]
        s = _scene(small, apparent)
        still = _track_of(s, small, [60.0 - 0.585, 70.0 - 116.4])
        assert s.decision.mover[0].sum() == 1 and s.decision.mover[0, still]

    def test_unaliased_radial_mover_equals_a_displaced_stationary_target(self, small):
        """The limitation behind the ladder: to first order a radial mover's subpatch
        displacements are those of a stationary target at its apparent position
        (y + v x / V, x - v R / V), so no displacement test can tell them apart."""
        v, y, x = 0.39, 10.0, 20.0
        apparent = [y + v * x / 200.0, x - v * (small.track.scene_range + y) / 200.0]
        moving = _scene(small, [y, x], (v, 0.0))
        still = _scene(small, apparent)
        c0 = moving.centers[0]
        expected = [apparent[0] - float(c0[0]), apparent[1] - float(c0[1])]
        a = moving.tracks.excess[0, _track_of(moving, small, expected)]
        b = still.tracks.excess[0, _track_of(still, small, expected)]
        torch.testing.assert_close(a, b, atol=0.03, rtol=0)
        assert a.abs().max() > 0.1  # both differ from the targets at other positions
