"""Streaks: the stationary-phase level of a target seen in an image of the wrong motion."""

from __future__ import annotations

import pytest
import torch

from tests.motion.conftest import make_params
from torchsar.motion import (
    GHOST_MARGIN,
    look_interference,
    look_plan,
    polar_format,
    refocus,
    streak_level,
    unwalk,
)
from torchsar.sar import simulate_phase_history

# (own speed, own fold, image speed, image fold): a still point in a speed image, a folded
# radial mover in the plain image and in a speed image (the diagonal streak), an along-track
# mover in a fold image.
CASES = [
    (0.0, 0, 4.0, 0),
    (0.0, 0, 16.0, 0),
    (0.0, -1, 0.0, 0),
    (0.0, -1, 6.0, 0),
    (6.0, 0, 0.0, -1),
]


@pytest.fixture(scope="module")
def table1():
    return make_params(image_size=(256, 512))


def _image(params, speed: float, fold: int, image_speed: float, image_fold: int):
    """Intensity (relative to the focused peak) of one point in the bank image of
    ``(image_speed, image_fold)``, and its offsets (m) from where it focuses."""
    v_r = 0.0 if fold == 0 else 2.0 * -fold  # 2 m/s per fold at x = 20: shown 100 m off
    vel = torch.tensor([[[v_r, speed]]], dtype=torch.float64)
    g = simulate_phase_history(
        torch.tensor([[[-19.0, 20.0]]], dtype=torch.float64), params.geometry, velocities=vel
    )
    img = polar_format(g, params)

    def bank(v: float, k: int):
        return unwalk(refocus(img, params, torch.tensor([v]))[:, 0], params, torch.tensor([k]))

    own = bank(speed, fold)[0, 0].abs().square()
    other = bank(image_speed, image_fold)[0, 0].abs().square() / own.max()
    r0, c0 = divmod(int(own.argmax()), own.shape[-1])
    rows, cols = torch.meshgrid(torch.arange(256), torch.arange(512), indexing="ij")
    dy, dx = params.pixel_spacing
    delta = torch.stack([(rows - r0) * dy, ((cols - c0 + 256) % 512 - 256) * dx], -1)
    return other.double(), delta.double()


@pytest.mark.parametrize("case", CASES)
def test_level_bounds_the_simulated_streak(table1, case):
    speed, fold, image_speed, image_fold = case
    intensity, delta = _image(table1, *case)
    drift = torch.tensor(
        [-(fold - image_fold) * table1.geometry.blind_speed, 2 * (speed - image_speed)],
        dtype=torch.float64,
    )
    level = streak_level(delta, drift.expand_as(delta), table1)
    on = level > 0
    assert float(intensity[~on].max()) < 0.01  # the streak is where the model puts it
    ratio = intensity[on] / level[on]
    assert float(ratio.max()) < GHOST_MARGIN  # the model covers it, ripples included
    assert float(ratio.quantile(0.99)) > 0.5  # and is not loose


def test_no_drift_no_streak(table1):
    delta = torch.tensor([[0.0, 0.0], [0.0, 3.0]], dtype=torch.float64)
    assert streak_level(delta, torch.zeros(2, 2), table1).tolist() == [0.0, 0.0]


def test_look_interference(table1):
    """A slow mover whose look position lies on a bright still target's streak (the look is
    refocused for the mover's speed) is interfered with; one far from it is not."""
    plan = look_plan(table1)
    position = torch.tensor([[[10.0, 0.0], [10.0, 6.0], [-50.0, -40.0]]], dtype=torch.float64)
    speed = torch.tensor([[0.0, 3.0, 3.0]], dtype=torch.float64)
    fold = torch.zeros(1, 3, dtype=torch.long)
    intensity = torch.tensor([[100.0, 1.0, 1.0]], dtype=torch.float64)
    valid = torch.ones(1, 3, dtype=torch.bool)
    eps = look_interference(position, speed, fold, intensity, valid, plan, table1)
    assert eps.shape == (1, 3, 2)
    assert float(eps[0, 1].max()) > 0.5 and float(eps[0, 2].max()) == 0.0
    assert float(eps[0, 0].max()) < 0.1  # the faint mover hardly disturbs the bright one
