"""Moving targets end to end: focus and look tests at each target's range, the verdict on
seeded random scenes (along-track and folded radial movers), honest sigmas, controls, batches."""

from __future__ import annotations

import math

import pytest
import torch

from tests.motion.conftest import make_params
from tests.motion.scenes import STILL as KIND_STILL
from tests.motion.scenes import random_scenes, score
from torchsar.errors import OptionError
from torchsar.motion import (
    find_movers,
    focus_step,
    polar_format,
    refocus,
    speed_bank,
)
from torchsar.sar import add_noise, image_noise_std, simulate_phase_history

STILL = [[-25.0, -20.0], [20.0, -8.0], [-5.0, 6.0]]


@pytest.fixture(scope="module")
def table1():
    return make_params(image_size=(128, 512))


def _scenes(params, velocities, snr_db=30.0, seed=0, mover=(10.0, 20.0)):
    """Three stationary targets and a mover per scene, ``velocities (B, 2)``."""
    b = len(velocities)
    pos = torch.tensor([[*STILL, mover]], dtype=torch.float64).expand(b, -1, -1).contiguous()
    vel = torch.zeros_like(pos)
    vel[:, 3] = torch.tensor(velocities, dtype=torch.float64)
    g = simulate_phase_history(pos, params.geometry, velocities=vel)
    g = add_noise(g, std=image_noise_std(params.geometry, snr_db), seed=seed)
    return g.to(torch.complex64)


def _index(report, b, where):
    """Target nearest the image position ``where`` (m)."""
    d = (report.position[b] - torch.tensor(where, dtype=torch.float64)).norm(dim=-1)
    return int(d.nan_to_num(nan=math.inf).argmin())


@pytest.fixture(scope="module")
def along(table1):
    speeds = [1.0, 3.0, 10.0]
    return speeds, find_movers(_scenes(table1, [(0.0, v) for v in speeds]), table1, subpatch=False)


class TestRefocus:
    def test_zero_speed_is_identity_and_bank_is_symmetric(self, table1):
        img = torch.randn(
            2, 8, 512, dtype=torch.complex64, generator=torch.Generator().manual_seed(0)
        )
        out = refocus(img, table1, torch.tensor([0.0]))[:, 0]
        assert torch.allclose(out, img, atol=1e-5)
        bank = speed_bank(16.0, focus_step(table1))
        assert torch.equal(bank, -bank.flip(0)) and bank.abs().max() >= 16.0

    def test_refocus_restores_a_mover_peak(self, table1):
        g = simulate_phase_history(
            torch.zeros(1, 1, 2), table1.geometry, velocities=torch.tensor([[[0.0, 6.0]]])
        )
        img = polar_format(g, table1)
        peaks = refocus(img, table1, torch.tensor([0.0, 6.0])).abs().flatten(-2).amax(-1)[0]
        assert peaks[0] < 0.3 and peaks[1] > 0.95


class TestAlongTrackMovers:
    def test_detected_by_both_tests_with_velocity_within_10_percent(self, along):
        speeds, r = along
        for b, v in enumerate(speeds):
            i = _index(r, b, [10.0, 20.0 * (1 - v / 200.0)])
            assert r.mover[b, i] and r.look.mover[b, i] and r.focus.mover[b, i]
            for est in (r.look.velocity, r.focus.velocity, r.velocity):
                assert abs(float(est[b, i]) - v) < 0.1 * v, (v, float(est[b, i]))
            dt = float(r.plan.time[-1] - r.plan.time[0])
            shift = float(r.look.displacement[b, i, -1, 1])
            assert abs(shift - (2 * v - v * v / 200.0) * dt) < 0.1 * 2 * v * dt

    def test_no_false_movers_and_stationary_targets_found(self, along):
        _, r = along
        for b in range(3):
            still = [_index(r, b, p) for p in STILL]
            assert (r.position[b, still] - torch.tensor(STILL)).norm(dim=-1).max() < 1.0
            assert int(r.mover[b].sum()) == 1 and not r.mover[b, still].any()

    def test_uncertainty_is_honest(self, along):
        """Stationary velocity estimates scatter within a few of their own sigmas."""
        _, r = along
        still = torch.stack([torch.tensor([_index(r, b, p) for p in STILL]) for b in range(3)])
        b = torch.arange(3)[:, None]
        for test in (r.look, r.focus):
            z = (test.velocity[b, still] / test.sigma[b, still]).abs()
            assert z.max() < 5.0


class TestOwnRange:
    @pytest.mark.parametrize("r", [-70.0, 70.0])
    def test_speed_at_the_targets_own_slant_range(self, table1, r):
        """At 70 m from the scene centre the centre's slant range would misjudge a 12 m/s
        mover by 0.7 % (84 mm/s); each target's own range leaves a fraction of that."""
        g = _scenes(table1, [(0.0, 12.0), (0.0, -12.0)], snr_db=50.0, mover=(r, 0.0))
        rep = find_movers(g, table1, subpatch=False)
        for b, v in enumerate([12.0, -12.0]):
            i = _index(rep, b, [r, 0.0])
            for est in (rep.look.velocity, rep.focus.velocity):
                assert abs(float(est[b, i]) - v) < 0.02, (r, v, float(est[b, i]))


class TestControlsAndEdgeCases:
    @pytest.mark.integration  # exhaustive: 20 scenes
    def test_no_false_mover_on_20_control_scenes_with_clutter(self, small):
        """Stationary targets plus 150 weak clutter scatterers and noise, 20 seeds."""
        gen = torch.Generator().manual_seed(7)
        ext = torch.tensor(small.image_extent, dtype=torch.float64)
        clutter = (torch.rand(20, 150, 2, generator=gen, dtype=torch.float64) - 0.5) * ext
        pos = torch.cat([torch.tensor([STILL], dtype=torch.float64).expand(20, -1, -1), clutter], 1)
        amp = torch.ones(20, pos.shape[1], dtype=torch.complex128)
        amp[:, 3:] = 0.05 * torch.randn(20, 150, generator=gen, dtype=torch.complex128)
        g = simulate_phase_history(pos, small.geometry, amplitudes=amp)
        g = add_noise(g, std=image_noise_std(small.geometry, 30.0), seed=7)
        r = find_movers(g.to(torch.complex64), small, subpatch=False)
        assert int(r.valid.sum(1).min()) >= 3  # the targets, and clutter peaks, are tested
        assert not r.mover.any()
        assert not (r.look.mover & r.focus.mover).any()

    def test_batch_invariance(self, small):
        g = _scenes(small, [(0.0, 2.0), (0.0, 0.0)], seed=3)
        whole = find_movers(g, small, subpatch=False)
        for b in range(2):
            one = find_movers(g[b : b + 1], small, subpatch=False)
            n = int(one.valid.sum())
            assert torch.equal(whole.pixel[b, :n], one.pixel[0, :n])
            assert torch.equal(whole.mover[b, :n], one.mover[0, :n])
            assert torch.allclose(
                whole.velocity[b, :n], one.velocity[0, :n], atol=1e-6, equal_nan=True
            )

    def test_empty_scenes_and_empty_batch(self, small):
        g = torch.zeros(2, small.geometry.pulses, small.geometry.samples, dtype=torch.complex64)
        r = find_movers(g, small, subpatch=False)
        assert r.mover.shape == (2, 0) and r.velocity.shape == (2, 0)
        r0 = find_movers(g[:0], small)
        assert r0.mover.shape[0] == 0

    def test_bad_options(self, small):
        g = torch.zeros(1, small.geometry.pulses, small.geometry.samples, dtype=torch.complex64)
        with pytest.raises(OptionError):
            find_movers(g, small, looks=1)
        with pytest.raises(OptionError):
            find_movers(g, small, n_sigma=0.0)


@pytest.fixture(scope="module")
def random12():
    """Twelve seeded random scenes at 28 dB (tests/motion/scenes.py) and their report."""
    params = make_params(image_size=(256, 512))
    g, scenes = random_scenes(params, 0, 12)
    return params, scenes, find_movers(g, params, subpatch=False)


class TestRandomScenes:
    """The acceptance on 12 random scenes (48 in the slow run): along-track movers found with
    honest velocities, folded radial movers flagged with their fold, nothing else flagged."""

    def test_along_track_movers(self, random12):
        params, scenes, report = random12
        t = score(report, scenes, params)
        assert t.along >= 12 and t.found == t.along and t.accurate == t.found, t.misses
        assert 0.5 <= t.rms_z <= 1.5  # (v_est - v_true) / sigma over ~16 movers
        assert t.false_movers == 0

    def test_folded_radial_movers(self, random12):
        params, scenes, report = random12
        t = score(report, scenes, params)
        assert t.folded >= 3 and t.streaks == t.folded
        assert t.radial_right == t.streaks, t.misses
        assert t.radial_elsewhere == 0 and t.unfolded_flagged == 0
        assert not (report.mover & report.radial).any()

    def test_honest_sigma_of_every_test(self, random12):
        """Stationary targets: each test's estimate (0 by construction) over its own sigma
        spreads like a standard normal, not wider (the look test's LOOK_SIGMA_FACTOR, the
        focus test's FOCUS_SIGMA_FACTOR, the walk's range bound were measured this way)."""
        params, scenes, report = random12
        period = torch.tensor(
            [params.geometry.unambiguous_range, params.geometry.unambiguous_azimuth],
            dtype=torch.float64,
        )
        z = {"look": [], "focus": [], "walk": []}
        for b, scene in enumerate(scenes):
            n = int(report.valid[b].sum())
            for j in (scene.kind == KIND_STILL).nonzero().flatten().tolist():
                d = (report.position[b, :n] - scene.image[j]).remainder(period)
                d = torch.minimum(d, period - d).norm(dim=-1)
                i = int(d.argmin())
                if float(d[i]) > 2.5 or not bool(report.look.seen[b, i]):
                    continue
                z["look"].append(float(report.look.velocity[b, i] / report.look.sigma[b, i]))
                z["focus"].append(float(report.focus.velocity[b, i] / report.focus.sigma[b, i]))
                z["walk"].append(float(report.look.walk[b, i] / report.look.walk_sigma[b, i]))
        for name, values in z.items():
            rms = math.sqrt(sum(v * v for v in values) / len(values))
            assert len(values) > 60 and 0.5 <= rms <= 1.2, (name, rms)
            assert max(abs(v) for v in values) < 4.5, name

    def test_an_along_track_mover_crossing_the_sampled_extent_is_a_conflict(self, table1):
        """13 m/s at 62 m: its track passes the edge of the 150 m sampled azimuth extent, so
        part of its aperture is folded and walks. It is neither an along-track nor a radial
        mover: a conflict."""
        g = _scenes(table1, [(0.0, 13.0)], snr_db=40.0, mover=(-20.0, 62.0))
        rep = find_movers(g, table1, subpatch=False)
        i = _index(rep, 0, [-20.0, 62.0 * (1 - 13 / 200)])
        assert bool(rep.conflict[0, i]) and not bool(rep.mover[0, i] | rep.radial[0, i])


@pytest.mark.slow
def test_acceptance_on_48_random_scenes():
    """Four seeds x 12 scenes at 28 dB: every along-track mover found, error within 3 % or
    2 sigma, rms of (v_est - v_true) / sigma in [0.7, 1.5], no false mover; every folded
    radial mover whose streak is detected flagged with its fold, nothing else radial."""
    params = make_params(image_size=(256, 512))
    t = None
    for seed in range(4):
        g, scenes = random_scenes(params, seed, 12)
        t = score(find_movers(g, params, subpatch=False), scenes, params, t)
    assert t.found == t.along and t.accurate == t.found, t.misses
    assert 0.7 <= t.rms_z <= 1.5 and t.false_movers == 0
    assert t.radial_right == t.streaks and t.radial_elsewhere == 0 and t.unfolded_flagged == 0
