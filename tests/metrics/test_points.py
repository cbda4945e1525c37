"""The distance rule in the harness's matcher (``match_batch`` with ``kind="distance"``):
per plane, at the operating point the most pairs closer than the tolerance with the least
total distance (a written-out brute force), the rest greedy by score; in pixels and in
metres with anisotropic pixels."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.reference.distance import brute_force_optimal, greedy_loop
from torchsar.metrics import Matching, ground_truth, match_batch
from torchsar.objects import Objects

SIZE = 32


def _case(rng, planes: int):
    inst = np.zeros((planes, SIZE, SIZE), np.int32)
    for p in range(planes):
        cells = rng.choice(SIZE * SIZE, int(rng.integers(0, 6)), replace=False)
        inst[p].reshape(-1)[cells] = np.arange(1, cells.size + 1)  # one-pixel instances
    n = rng.integers(0, 7, planes)
    plane = np.repeat(np.arange(planes), n)
    points = rng.integers(0, SIZE, (plane.size, 2)).astype(np.float64)
    scores = rng.choice([0.2, 0.6, 0.9, 1.4, 2.0], plane.size)  # ties on purpose
    return inst, Objects.from_points(
        points, scores, shape=(SIZE, SIZE), plane=plane, planes=planes, threshold=1.0
    )


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), units=st.sampled_from(["px", "m"]))
def test_distance_rule_equals_brute_force_and_greedy_loop(seed, units):
    rng = np.random.default_rng(seed)
    inst, obj = _case(rng, 3)
    spacing = np.tile([0.5, 2.0], (3, 1))
    gt = ground_truth(inst, spacing=spacing)
    rule = Matching(kind="distance", max_distance=5.0, distance_units=units)
    m = match_batch(obj, gt, rule)
    scale = np.array([0.5, 2.0]) if units == "m" else np.ones(2)
    for p in range(3):
        d = np.flatnonzero(obj.plane == p)
        d = d[np.argsort(-obj.score[d], kind="stable")]
        g = np.flatnonzero(gt.plane == p)
        diff = (obj.centroid[d][:, None, :] - gt.centroid[g][None, :, :]) * scale
        dist = np.hypot(diff[..., 0], diff[..., 1])
        # AP / FROC: the greedy visit by score
        ref = greedy_loop(dist, obj.score[d], 5.0)
        expect = np.where(ref >= 0, g[np.maximum(ref, 0)], -1) if g.size else ref
        assert np.array_equal(m.ap[0, 0, d], expect)
        # operating point (score > 1): optimal among those; the others greedy on what is left
        top = obj.score[d] > 1.0
        pairs, total = brute_force_optimal(dist[top], 5.0)
        op_top = m.op[d][top]
        got_cols = np.searchsorted(g, op_top[op_top >= 0])
        assert (op_top >= 0).sum() == pairs
        assert np.isclose(dist[top][op_top >= 0, got_cols].sum(), total)
        free = np.setdiff1d(np.arange(g.size), got_cols)
        rest = greedy_loop(dist[~top][:, free], obj.score[d][~top], 5.0)
        expect = np.where(rest >= 0, g[free[np.maximum(rest, 0)]] if free.size else -1, -1)
        assert np.array_equal(m.op[d][~top], expect)
