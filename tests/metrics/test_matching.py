from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.reference.coco import coco_match, random_problems
from torchsar.errors import OptionError
from torchsar.metrics import Matching, box_iou, greedy_match, ground_truth, match_batch
from torchsar.metrics.greedy import assign_pairs, greedy_assign
from torchsar.metrics.matching import COCO_IOUS
from torchsar.objects import ObjectRules, discriminate


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), d=st.integers(0, 7), g=st.integers(0, 5))
def test_greedy_equals_the_pycocotools_loop(seed, d, g):
    rng = np.random.default_rng(seed)
    q = rng.choice([0.0, 0.3, 0.5, 0.55, 0.7, 0.9, 1.0], size=(d, g))  # ties on purpose
    crowd = rng.choice([0.0, 0.5, 0.8], size=d)
    got = greedy_match(q, crowd, COCO_IOUS)
    ref = coco_match(
        np.concatenate([q, crowd[:, None]], axis=1), np.r_[np.zeros(g), 1] > 0, COCO_IOUS
    )
    assert np.array_equal(got, np.where(ref == g, -2, ref))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), problems=st.integers(1, 6))
def test_problems_at_once_equal_the_pycocotools_loop_per_problem(seed, problems):
    """Many problems matched from their candidate pairs (with ties and crowd columns) equal the literal loop on each problem."""
    rng = np.random.default_rng(seed)
    sizes = rng.integers(0, 8, (problems, 2))
    d_problem = np.repeat(np.arange(problems), sizes[:, 0])
    g_problem = np.repeat(np.arange(problems), sizes[:, 1] + 1)  # + one crowd column each
    crowd = np.concatenate([np.r_[np.zeros(g), 1] > 0 for g in sizes[:, 1]])
    blocks, pairs = [], ([], [], [])
    d0 = g0 = 0
    for d, g in sizes:
        q = rng.choice([0.0, 0.3, 0.5, 0.55, 0.7, 0.9, 1.0], size=(d, g + 1))
        blocks.append(q)
        i, j = np.nonzero(q > 0)
        for a, v in zip(pairs, (i + d0, j + g0, q[i, j]), strict=True):
            a.append(v)
        d0, g0 = d0 + d, g0 + g + 1
    flat = tuple(np.concatenate(a) for a in pairs)
    col = assign_pairs(d_problem, g_problem, crowd[:, None], crowd, flat, COCO_IOUS)[:, 0, :]
    d0 = g0 = 0
    for (d, g), q in zip(sizes, blocks, strict=True):
        ref = coco_match(q, np.r_[np.zeros(g), 1] > 0, COCO_IOUS)
        got = col[d0 : d0 + d].T - g0
        got = np.where(col[d0 : d0 + d].T < 0, -1, np.where(got == g, -2, got))
        assert np.array_equal(got, ref)
        d0, g0 = d0 + d, g0 + g + 1


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), problems=st.integers(1, 6))
def test_problems_with_ignored_instances_per_area_range_equal_the_dense_matcher(seed, problems):
    """Instances ignored in some area ranges and not others, crowd ones, tied qualities:
    the pair-by-pair matcher equals the padded one, problem by problem."""
    rng = np.random.default_rng(seed)
    d_problem, g_problem, ignore, crowd, flat, dense = random_problems(rng, problems, 3)
    col = assign_pairs(d_problem, g_problem, ignore, crowd, flat, COCO_IOUS)
    d0 = g0 = 0
    for q in dense:
        d, g = q.shape
        quality = np.where(q > 0, q, -np.inf)[None]
        ref = greedy_assign(
            quality, ignore[g0 : g0 + g].T[None], crowd[g0 : g0 + g][None], np.array([d]), COCO_IOUS
        )[0]
        got = col[d0 : d0 + d]
        assert np.array_equal(np.where(got >= 0, got - g0, -1), ref)
        d0, g0 = d0 + d, g0 + g


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), d=st.integers(0, 12), g=st.integers(0, 1))
def test_greedy_with_at_most_one_instance_equals_the_pycocotools_loop(seed, d, g):
    """The loop-free path for chips with one target (or none)."""
    rng = np.random.default_rng(seed)
    q = rng.choice([0.0, 0.3, 0.5, 0.55, 0.7, 0.9, 1.0], size=(d, g))
    crowd = rng.choice([0.0, 0.5, 0.8, 1.0], size=d)
    thresholds = np.r_[COCO_IOUS, 1e-12]
    got = greedy_match(q, crowd, thresholds)
    ref = coco_match(
        np.concatenate([q, crowd[:, None]], axis=1), np.r_[np.zeros(g), 1] > 0, thresholds
    )
    assert np.array_equal(got, np.where(ref == g, -2, ref))


def test_box_iou_hand_computed():
    a = np.array([[0, 0, 4, 4.0]])
    b = np.array([[2, 2, 6, 6.0], [10, 10, 12, 12.0]])
    assert box_iou(a, b).tolist() == [[4 / 28, 0.0]]
    assert box_iou(a, b, crowd=True).tolist() == [[4 / 16, 0.0]]


def test_matching_options_are_validated():
    with pytest.raises(OptionError, match="kind"):
        Matching(kind="touch")
    with pytest.raises(OptionError, match="iou"):
        Matching(iou=1.5)
    with pytest.raises(OptionError, match="max_size_ratio"):
        Matching(kind="centroid", max_size_ratio=0.5)


def _score(stat: np.ndarray, inst: np.ndarray, rule: Matching, ignore=None, closing=0):
    s = torch.as_tensor(stat, dtype=torch.float64)[:, None]
    obj = discriminate(s, 1.0, rules=ObjectRules(closing=closing))
    gt = ground_truth(inst, ignore)
    return match_batch(obj, gt, rule), obj, gt


def _two_targets():
    inst = np.zeros((1, 40, 40), int)
    inst[0, 5:25, 5:20] = 1  # a large target ...
    inst[0, 10:16, 22:28] = 2  # ... and a small one beside it
    return inst


@pytest.mark.parametrize("kind", ["mask", "box", "centroid"])
def test_one_blob_over_two_targets_is_one_tp_and_one_fn(kind):
    inst = _two_targets()
    stat = np.zeros((1, 40, 40))
    stat[0, 5:25, 5:28] = 3.0  # one blob covering both
    m, obj, _ = _score(stat, inst, Matching(kind=kind))
    assert len(obj) == 1 and (m.op >= 0).sum() == 1 and m.op[0] == 0
    assert np.isfinite(m.gt_score).sum() == 1  # the small target is missed


@pytest.mark.parametrize("kind", ["mask", "centroid"])
def test_flood_is_one_false_alarm(kind):
    inst = _two_targets()
    m, obj, _ = _score(np.full((1, 40, 40), 5.0), inst, Matching(kind=kind))
    assert len(obj) == 1 and m.op.tolist() == [-1]


def test_split_target_one_tp_rest_false_unless_closed():
    inst = np.zeros((1, 30, 30), int)
    inst[0, 5:15, 5:15] = 1
    stat = np.zeros((1, 30, 30))
    stat[0, 5:15, 5:9] = 2.0
    stat[0, 5:15, 11:15] = 4.0  # two fragments two pixels apart
    m, obj, _ = _score(stat, inst, Matching(kind="centroid"))
    assert len(obj) == 2 and sorted(m.op.tolist()) == [-1, 0]
    m, obj, _ = _score(stat, inst, Matching(kind="mask"), closing=2)
    assert len(obj) == 1 and m.op.tolist() == [0]


def test_detection_in_ignore_region_is_neither_tp_nor_fp():
    inst = np.zeros((1, 20, 20), int)
    inst[0, 2:6, 2:6] = 1
    ignore = np.zeros((1, 20, 20), bool)
    ignore[0, 12:18, 12:18] = True
    stat = np.zeros((1, 20, 20))
    stat[0, 13:16, 13:16] = 2.0
    for kind in ("mask", "box", "centroid"):
        m, _, _ = _score(stat, inst, Matching(kind=kind), ignore=ignore)
        assert m.op.tolist() == [-2]


def test_higher_score_wins_the_target():
    inst = np.zeros((1, 20, 20), int)
    inst[0, 2:12, 2:12] = 1
    stat = np.zeros((1, 20, 20))
    stat[0, 2:12, 2:6] = 2.0  # weaker, smaller overlap
    stat[0, 2:12, 8:12] = 9.0
    m, obj, _ = _score(stat, inst, Matching(kind="centroid"))
    strong = int(np.argmax(obj.score))
    assert m.op[strong] == 0 and m.op[1 - strong] == -1


def test_ground_truth_ids_classes_and_empty_planes():
    inst = np.zeros((3, 6, 6), int)
    inst[0, 1:3, 1:3] = 1
    inst[0, 4:6, 4:6] = 2
    inst[2, 0:2, 0:2] = 5
    gt = ground_truth(inst, classes=[["a", "b"], [], [None, None, None, None, "c"]])
    assert gt.plane.tolist() == [0, 0, 2]
    assert list(gt.classes) == ["a", "b", "c"]
    assert gt.box.tolist() == [[1, 1, 3, 3], [4, 4, 6, 6], [0, 0, 2, 2]]
    assert gt.area.tolist() == [4, 4, 4]


def _reference_plane(obj, gt, p, rule):
    """Brute force for one plane: pixel IoUs from the label maps, COCO's loop per threshold."""
    d = obj.in_plane(p)
    d = d[np.argsort(-obj.score[d], kind="stable")]
    g = np.flatnonzero(gt.plane == p)
    lab, ids, ign = obj.labels[p], gt.ids[p], gt.ignore[p]
    iou = np.zeros((d.size, g.size))
    for i, di in enumerate(d):
        for j, gj in enumerate(g):
            a, b = lab == di + 1, ids == gj + 1
            iou[i, j] = (a & b).sum() / (a | b).sum()
    crowd = np.array([(ign & (lab == di + 1)).sum() / max(obj.area[di], 1) for di in d])
    if rule.iou_kind == "box":  # the boxes' area on the ignore pixels (unit squares)
        iou, crowd = box_iou(obj.box[d], gt.box[g]), np.zeros(d.size)
        for i, di in enumerate(d):
            r0, c0, r1, c1 = obj.box[di]
            for r, c in zip(*np.nonzero(ign), strict=True):
                ov = max(0.0, min(r + 1, r1) - max(r, r0)) * max(0.0, min(c + 1, c1) - max(c, c0))
                crowd[i] += ov / ((r1 - r0) * (c1 - c0))
    ap = coco_match(np.c_[iou, crowd], np.r_[np.zeros(g.size), 1] > 0, COCO_IOUS)
    if rule.kind == "centroid":
        q = np.zeros((d.size, g.size))
        for i, di in enumerate(d):
            cy, cx = obj.centroid[di] + 0.5
            for j, gj in enumerate(g):
                r0, c0, r1, c1 = gt.box[gj]
                m = rule.margin * max(r1 - r0, c1 - c0)
                db = obj.box[di]
                small = (db[2] - db[0]) * (db[3] - db[1]) <= rule.max_size_ratio * (r1 - r0) * (
                    c1 - c0
                )
                if r0 - m <= cy <= r1 + m and c0 - m <= cx <= c1 + m and small:
                    q[i, j] = 1 / (1 + np.hypot(cy - (r0 + r1) / 2, cx - (c0 + c1) / 2))
        op = coco_match(np.c_[q, (crowd >= 0.5) * 1.0], np.r_[np.zeros(g.size), 1] > 0, [1e-12])[0]
    else:
        op = coco_match(np.c_[iou, crowd], np.r_[np.zeros(g.size), 1] > 0, [rule.iou])[0]

    def code(a):  # reference columns -> instance indices; the crowd column -> -2
        inst = np.r_[g, -2, -1]
        return inst[np.where(a == -2, g.size, np.where(a == -1, g.size + 1, a))]

    return d, code(ap), code(op)


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    kind=st.sampled_from(["mask", "box", "centroid"]),
    iou=st.sampled_from([0.5, 0.3]),
)
def test_match_batch_equals_brute_force_per_plane(seed, kind, iou):
    """Planes with 0, 1 and several instances in one batch (the first two kinds are matched
    all at once, the last plane by plane)."""
    rng = np.random.default_rng(seed)
    n, size = 6, 24
    inst = np.zeros((n, size, size), int)
    for p in range(n):
        for i in range(1, int(rng.choice([0, 1, 1, 2, 3])) + 1):
            r, c = rng.integers(0, size - 6, 2)
            inst[p, r : r + rng.integers(2, 7), c : c + rng.integers(2, 7)] = i
    ignore = (rng.random((n, size, size)) < 0.05) & (inst == 0)
    stat = rng.random((n, size, size)) * (rng.random((n, size, size)) < 0.25) * 4
    stat[inst > 0] += rng.random() * 3
    rule = Matching(kind=kind, iou=iou)
    m, obj, gt = _score(stat, inst, rule, ignore=ignore)
    for p in range(n):
        d, ap, op = _reference_plane(obj, gt, p, rule)
        assert np.array_equal(m.ap[0][:, d], ap) and np.array_equal(m.op[d], op)
