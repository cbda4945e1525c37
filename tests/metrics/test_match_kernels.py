"""The compiled matching kernels (greedy assignment, pixel joins) against the numpy code they
replace, which the other matching tests hold to pycocotools' own loop: the same choices,
pairs and counts on random problems with ties, crowd and ignored instances, overlapping
and unsorted pixel lists; and whole batches matched the same both ways."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.reference.coco import random_problems
from torchsar import _jit
from torchsar.metrics import Matching, match_batch
from torchsar.metrics.assign import join_pixels
from torchsar.metrics.greedy import assign_pairs
from torchsar.metrics.matching import COCO_IOUS
from torchsar.metrics.truth import GroundTruth, Regions
from torchsar.objects import ObjectRules, discriminate

pytestmark = pytest.mark.skipif(not _jit.enabled(), reason="numba kernels not available")


def _both(fn):
    """``fn()`` with the compiled kernels, then with the numpy code."""
    out = []
    for on in (True, False):
        with pytest.MonkeyPatch.context() as m:
            m.setattr(_jit, "ENABLED", on)
            out.append(fn())
    return out


def _lists(rng, n_lists: int, top: int, overlap: bool, ascending: bool):
    """``n_lists`` pixel lists (some empty) over ``[0, top)``: owners and pixels, disjoint
    unless ``overlap``, in ascending pixel order or shuffled."""
    owner, pix = [], []
    taken = set()
    for k in range(n_lists):
        size = int(rng.integers(0, 30))
        cand = rng.choice(top, size=min(size, top), replace=False)
        if not overlap:
            cand = np.array([p for p in cand if p not in taken], np.int64)
            taken.update(cand.tolist())
        owner.append(np.full(cand.size, k))
        pix.append(np.sort(cand))
    owner, pix = np.concatenate(owner).astype(np.int64), np.concatenate(pix).astype(np.int64)
    order = np.argsort(pix, kind="stable") if ascending else rng.permutation(pix.size)
    return owner[order], pix[order]


@settings(max_examples=120, deadline=None)
@given(
    seed=st.integers(0, 100_000),
    overlap=st.booleans(),
    a_sorted=st.booleans(),
    b_sorted=st.booleans(),
    top=st.sampled_from([5, 60, 4000]),
)
def test_the_compiled_join_is_the_numpy_join(seed, overlap, a_sorted, b_sorted, top):
    rng = np.random.default_rng(seed)
    a = _lists(rng, int(rng.integers(1, 8)), top, True, a_sorted)
    b = _lists(rng, int(rng.integers(1, 8)), top, overlap, b_sorted)
    got, want = _both(lambda: join_pixels(*a, *b))
    for g, w in zip(got, want, strict=True):
        assert g.dtype == np.int64 and np.array_equal(g, w)


def test_the_compiled_join_counts_a_pixel_in_two_lists_twice():
    a_owner, a_pix = np.array([0, 0, 1]), np.array([3, 5, 5])
    b_owner, b_pix = np.array([1, 0, 1, 0]), np.array([5, 5, 9, 3])  # 5 in both b lists
    got, want = _both(lambda: join_pixels(a_owner, a_pix, b_owner, b_pix))
    assert [v.tolist() for v in got] == [[0, 0, 1, 1], [0, 1, 0, 1], [2, 1, 1, 1]]
    assert all(np.array_equal(g, w) for g, w in zip(got, want, strict=True))


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 100_000), problems=st.integers(1, 7))
def test_the_compiled_greedy_makes_the_numpy_choices(seed, problems):
    """Ties in quality, crowd instances, instances ignored in some area ranges only, one
    and several thresholds (the operating point's and COCO's ten)."""
    rng = np.random.default_rng(seed)
    d_problem, g_problem, ignore, crowd, flat, _ = random_problems(rng, problems, 4)
    for thresholds in (COCO_IOUS, [0.5], [1e-12]):
        got, want = _both(
            lambda t=thresholds: assign_pairs(d_problem, g_problem, ignore, crowd, flat, t)
        )
        assert np.array_equal(got, want)


@pytest.mark.parametrize("kind", ["mask", "box", "centroid"])
@pytest.mark.parametrize("seed", range(4))
def test_batches_are_matched_the_same_both_ways(kind, seed):
    """Discriminated objects of a speckled batch against overlapping instances and a
    don't-care region per plane: every field of the batch's match is the same."""
    g = torch.Generator().manual_seed(seed)
    h, w = 48, 40
    x = torch.empty(4, 1, h, w).exponential_(generator=g)
    plane, box, pixels = [], [], []
    for p in range(4):
        r, c = torch.randint(6, 36, (2,), generator=g).tolist()
        x[p, 0, r : r + 6, c : c + 5] += 30.0
        for r0, r1, c0, c1 in [(r - 1, r + 5, c, c + 6), (r + 3, r + 8, c + 2, c + 4)]:
            rr, cc = np.meshgrid(np.arange(r0, r1), np.arange(c0, c1), indexing="ij")
            plane.append(p)
            box.append((r0, c0, r1, c1))
            pixels.append((rr * w + cc).reshape(-1))  # the two overlap
    corner = (np.arange(6)[:, None] * w + np.arange(6)[None, :]).reshape(-1)
    crowd = Regions.build(
        np.arange(4), np.tile([0.0, 0, 6, 6], (4, 1)), shape=(h, w), pixels=[corner] * 4
    )
    gt = GroundTruth.build(
        np.array(plane),
        np.array(box, np.float64),
        planes=4,
        shape=(h, w),
        pixels=pixels,
        crowd=crowd,
    )
    obj = discriminate(x, 8.0, rules=ObjectRules(min_area=1))
    rule = Matching(kind=kind)
    got, want = _both(lambda: match_batch(obj, gt, rule))
    assert len(obj) > 4 and (got.op >= 0).any() and (got.op == -1).any()
    for name in ("ap", "op", "op_iou", "gt_score", "overlaps", "gt_det"):
        assert np.array_equal(getattr(got, name), getattr(want, name)), name
