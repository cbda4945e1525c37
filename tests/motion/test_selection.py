"""repack: the kept targets of each scene, in order, against a loop over scenes."""

from __future__ import annotations

import math

import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from torchsar.motion import FocusTest
from torchsar.motion.selection import repack


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 1000), b=st.integers(0, 3), n=st.integers(0, 5))
def test_repack_matches_a_loop(seed, b, n):
    gen = torch.Generator().manual_seed(seed)
    keep = torch.rand(b, n, generator=gen) < 0.6
    values = torch.randn(b, n, generator=gen, dtype=torch.float64)
    mover = torch.rand(b, n, generator=gen) < 0.5
    f = FocusTest(values, values + 1, values + 2, values + 3, values + 4, mover)
    out = repack(f, keep)
    m = int(keep.sum(1).max()) if b else 0
    assert out.velocity.shape == (b, m)
    for i in range(b):
        kept = values[i][keep[i]]
        k = len(kept)
        assert torch.equal(out.velocity[i, :k], kept) and torch.equal(out.gain[i, :k], kept + 2)
        assert torch.equal(out.mover[i, :k], mover[i][keep[i]])
        assert all(math.isnan(x) for x in out.velocity[i, k:].tolist())
        assert not out.mover[i, k:].any()
