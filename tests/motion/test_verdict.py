"""The verdict's rules on hand-made test results, against the rules written out."""

from __future__ import annotations

import math

import pytest
import torch

from tests.motion.conftest import make_params
from torchsar.motion import FocusTest, LookTest, verdict

B = 3.0 * 0.99930819  # lambda PRF / 2 of Table 1, m/s

# rows: (v_look, s_look, v_focus, s_focus, walk, s_walk, bank fold, expected)
ROWS = [
    (0.00, 0.01, 0.00, 0.01, 0.0, 0.03, 0, "still"),
    (5.00, 0.01, 5.02, 0.01, 0.0, 0.03, 0, "mover"),  # 1.4 combined sigmas apart: agree
    (5.00, 0.01, 5.10, 0.01, 0.0, 0.03, 0, "conflict"),  # 7 sigmas apart
    (0.00, 0.01, 0.40, 0.05, 3 * -B / 3, 0.03, 1, "radial"),  # fold 1 walks -B m/s
    (0.00, 0.01, 0.00, 0.01, 2 * B, 0.03, -2, "radial"),
    (0.00, 0.01, 0.00, 0.01, 1.5 * B, 0.03, -1, "conflict"),  # half a fold: not an integer
    (0.00, 0.01, 0.00, 0.01, 2 * B, 0.03, 0, "conflict"),  # the bank saw no fold
    (0.00, 0.01, 0.00, 0.01, 3 * B, 0.03, -2, "radial"),  # beyond the bank's last fold
    (6.00, 0.01, 6.00, 0.01, 0.2, 0.03, 0, "mover"),  # a few hundredths of a fold: no walk
    (6.00, 0.01, 6.00, 0.01, -B, 0.03, 1, "radial"),  # walks: never an along-track mover
]


def _tests(rows):
    t = torch.tensor([r[:7] for r in rows], dtype=torch.float64)[None]
    nan, yes = torch.full_like(t[..., 0], math.nan), torch.ones_like(t[..., 0], dtype=torch.bool)
    look = LookTest(
        displacement=torch.zeros(*t.shape[:2], 2, 2),
        rate=2 * t[..., 0],
        velocity=t[..., 0],
        sigma=t[..., 1],
        snr=torch.full((*t.shape[:2], 2), 500.0),
        score=t[..., 0].abs() / t[..., 1],
        mover=t[..., 0].abs() > 5 * t[..., 1],
        walk=t[..., 4],
        walk_sigma=t[..., 5],
        interference=torch.zeros(*t.shape[:2], 2),
        seen=yes,
    )
    focus = FocusTest(
        velocity=t[..., 2],
        sigma=t[..., 3],
        gain=nan,
        snr=nan,
        score=t[..., 2].abs() / t[..., 3],
        mover=t[..., 2].abs() > 5 * t[..., 3],
    )
    return look, focus, t[..., 6].long()


def test_rules():
    p = make_params()
    look, focus, bank = _tests(ROWS)
    position = torch.zeros(1, len(ROWS), 2, dtype=torch.float64)
    v = verdict(look, focus, bank, position, p, max_fold=2)
    kinds = [
        "mover" if m else "radial" if r else "conflict" if c else "still"
        for m, r, c in zip(v.mover[0], v.radial[0], v.conflict[0], strict=True)
    ]
    assert kinds == [r[-1] for r in ROWS]
    assert not (v.mover & v.radial).any() and not (v.conflict & (v.mover | v.radial)).any()
    assert v.fold[0].tolist() == [0, 0, 0, 1, -2, 0, 0, -3, 0, 1]
    assert torch.isnan(v.radial_speed[~v.radial]).all()
    lo, hi = v.radial_speed[0, 4].tolist()  # fold -2 shown at the centre: 6 m/s +- 2 m/s
    assert lo == pytest.approx(2 * B - 2.0, abs=1e-6) and hi == pytest.approx(2 * B + 2.0, abs=1e-6)


def test_velocity_is_the_inverse_variance_mean():
    p = make_params()
    look, focus, bank = _tests([(4.0, 0.02, 4.03, 0.01, 0.0, 0.03, 0, "")])
    v = verdict(look, focus, bank, torch.zeros(1, 1, 2), p)
    w1, w2 = 1 / 0.02**2, 1 / 0.01**2
    assert float(v.velocity) == pytest.approx((w1 * 4.0 + w2 * 4.03) / (w1 + w2))
    assert float(v.sigma) == pytest.approx((w1 + w2) ** -0.5)
    assert float(v.discrepancy) == pytest.approx(0.03 / math.hypot(0.02, 0.01))
    strict = verdict(look, focus, bank, torch.zeros(1, 1, 2), p, agree_sigma=1.0)
    assert bool(strict.conflict) and not bool(strict.mover)
