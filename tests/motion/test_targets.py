"""Targets over the motion bank: one detection per target, no streak ghosts, weak neighbours kept."""

from __future__ import annotations

import math

import pytest
import torch

from tests.motion.conftest import make_params
from torchsar.motion import bank_detect, detect_targets, polar_format, smear_ghosts, speed_bank
from torchsar.motion.peaks import default_detector
from torchsar.sar import add_noise, image_noise_std, simulate_phase_history


@pytest.fixture(scope="module")
def table1():
    return make_params(image_size=(256, 512))


def _image(params, positions, velocities, amplitudes, snr_db=28.0, seed=0):
    g = simulate_phase_history(
        positions, params.geometry, velocities=velocities, amplitudes=amplitudes
    )
    g = add_noise(g, std=image_noise_std(params.geometry, snr_db), seed=seed)
    return polar_format(g.to(torch.complex64), params)


def _positions(params, pixel):
    spacing = torch.tensor(params.pixel_spacing, dtype=torch.float64)
    return (pixel.double() - torch.tensor([128, 256])) * spacing


def _found(params, targets, b, where, gate=1.5):
    pos = _positions(params, targets.pixel[b][targets.valid[b]])
    d = (pos - torch.tensor(where, dtype=torch.float64)).norm(dim=-1)
    return int((d <= gate).sum())


class TestWeakNeighbours:
    @pytest.mark.parametrize("seed", [0, 1])
    def test_weak_stationary_in_a_bright_neighbours_range_cell_is_kept(self, table1, seed):
        """A scatterer 16 dB weaker than a stationary neighbour 20 m away in the same range
        cell: the neighbour's streaks over the speed bank stay below it there (about -24 dB),
        so it is no ghost. A rule based on distance alone (weaker than ``2 I rho / d``) and
        blind to both being found still dropped it."""
        pos = torch.tensor([[[10.0, -12.0], [10.0, 8.0], [-40.0, 30.0], [50.0, -30.0]]])
        amp = torch.tensor([[10 ** (16 / 20), 1.0, 1.0, 1.0]], dtype=torch.complex128)
        targets = detect_targets(_image(table1, pos.double(), None, amp, seed=seed), table1)
        assert _found(table1, targets, 0, [10.0, 8.0]) == 1
        assert _found(table1, targets, 0, [10.0, -12.0]) == 1
        rho = 1.44 * table1.geometry.cross_range_resolution
        assert 2 * 10**1.6 * rho / 20.0 > 1.0  # the distance rule would have dropped it

    def test_still_peak_beside_a_mover_is_kept_and_the_smear_is_not(self, table1):
        pix = torch.tensor([[10, 100], [10, 140], [10, 180], [10, 300]])
        v = torch.tensor([8.0, 0.0, 0.0, 0.0], dtype=torch.float64)
        value = torch.tensor([1e4, 50.0, 5e3, 40.0])
        ghost = smear_ghosts(pix, value, v, torch.zeros(4), table1, (256, 512))
        # 11.7 m away: on the mover's 40 m streak and below it; 23 m: beyond it, brighter;
        # 58 m: beyond the streak
        assert ghost.tolist() == [False, True, False, False]


class TestBank:
    def test_one_detection_per_target_and_the_bank_motion(self, table1):
        """A still target, along-track movers and a folded radial mover, each found once
        (no peaks along smears or the radial streak) with the bank's motion."""
        pos = torch.tensor([[[-40.0, -30.0], [10.0, -20.0], [30.0, 25.0], [-20.0, 40.0]]])
        vel = torch.zeros_like(pos)
        vel[0, 1, 1], vel[0, 2, 1] = 6.0, -11.0
        vel[0, 3, 0] = 4.4  # shown at 40 - 222 + 150 = -32 m: fold -1
        amp = torch.full((1, 4), 10 ** (10 / 20), dtype=torch.complex128)
        img = _image(table1, pos.double(), vel.double(), amp)
        t = detect_targets(img, table1, max_fold=2)
        assert int(t.valid.sum()) == 4
        step = 1.5 * 0.96
        found = {
            tuple(_positions(table1, p).round().tolist()): (float(v), int(k))
            for p, v, k in zip(t.pixel[0], t.speed[0], t.fold[0], strict=True)
        }
        motions = sorted(found.values())
        assert motions[0][0] == pytest.approx(-11.0, abs=step / 2)
        assert motions[-1][0] == pytest.approx(6.0, abs=step / 2)
        assert sorted(k for _, k in motions) == [-1, 0, 0, 0]

    def test_bank_images_and_batch(self, table1):
        img = _image(table1, torch.zeros(2, 1, 2, dtype=torch.float64), None, None)
        speeds = speed_bank(4.0, 2.0)
        res_px = (1.42, 1.02)
        bank = bank_detect(img, table1, speeds, default_detector(res_px), folds=torch.arange(-1, 2))
        assert bank.best.shape == (2, 1, 256, 512) and bank.fold.dtype == torch.long
        assert bank.speed[0, 0, 128, 256] == 0 and bank.fold[0, 0, 128, 256] == 0
        one = bank_detect(
            img[1:], table1, speeds, default_detector(res_px), folds=torch.arange(-1, 2)
        )
        assert torch.equal(one.mask[0], bank.mask[1]) and torch.equal(one.fold[0], bank.fold[1])
        assert math.isclose(float(one.best.max()), float(bank.best[1].max()), rel_tol=1e-5)
