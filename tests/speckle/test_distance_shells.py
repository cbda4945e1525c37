"""``windows.distance_shells`` / ``windows.exp_distance_mean`` (the Frost machinery)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from torchsar.windows import distance_shells, exp_distance_mean


def _loop(x: np.ndarray, decay: np.ndarray, r: int) -> np.ndarray:
    """Per-pixel weighted mean over the in-image cells of the box."""
    h, w = x.shape
    out = np.empty_like(x)
    for i in range(h):
        for j in range(w):
            num = den = 0.0
            for di in range(-r, r + 1):
                for dj in range(-r, r + 1):
                    if 0 <= i + di < h and 0 <= j + dj < w:
                        wt = math.exp(-decay[i, j] * math.hypot(di, dj))
                        num += wt * x[i + di, j + dj]
                        den += wt
            out[i, j] = num / den
    return out


def test_shells_partition_the_box():
    for radius in range(6):
        offsets = set()
        for d2, orbits in distance_shells(radius):
            for p, q in orbits:
                assert p * p + q * q == d2
                for a, b in ((p, q), (q, p)):
                    offsets |= {(sa * a, sb * b) for sa in (1, -1) for sb in (1, -1)}
        assert len(offsets) == (2 * radius + 1) ** 2
    assert dict(distance_shells(5))[25] == ((0, 5), (3, 4))  # two orbits, one distance


@settings(max_examples=15, deadline=None)
@given(
    radius=st.integers(1, 5),
    h=st.integers(1, 14),
    w=st.integers(1, 14),
    strip=st.sampled_from([None, 1, 3]),
    seed=st.integers(0, 2**16),
)
def test_matches_loop(radius, h, w, strip, seed):
    g = torch.Generator().manual_seed(seed)
    x = torch.rand((2, 1, h, w), generator=g, dtype=torch.float64)
    decay = 3 * torch.rand((2, 1, h, w), generator=g, dtype=torch.float64)
    got = exp_distance_mean(x, radius, decay, strip=strip)
    for b in range(2):
        want = _loop(x[b, 0].numpy(), decay[b, 0].numpy(), radius)
        np.testing.assert_allclose(got[b, 0].numpy(), want, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_extreme_decay_keeps_the_centre(dtype):
    x = torch.rand(1, 2, 9, 9, dtype=dtype)
    for decay in (1e6, torch.inf):
        out = exp_distance_mean(x, 3, torch.full_like(x, decay))
        assert torch.equal(out, x)
    assert exp_distance_mean(x[:0], 3, x[:0]).shape == (0, 2, 9, 9)
