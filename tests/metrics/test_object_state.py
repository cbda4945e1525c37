"""ObjectState: exact ranked metrics from per-detection records. AP equals pycocotools, the
metrics and every bootstrap replicate equal slow references written out, states merge in any
split and order, a strictly increasing map of the scores changes no number, and every
interval contains its point."""

from __future__ import annotations

import contextlib
import io
import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.reference import ranked as ref
from torchsar.metrics import Matching, ObjectState, ground_truth, match_batch
from torchsar.metrics.bootstrap import poisson_weights, unit_hash
from torchsar.metrics.curves import (
    coco_ap,
    coco_ap_rows,
    levels,
    partial_auc,
    pd_at_fa,
)
from torchsar.metrics.object_state import ImageInfo
from torchsar.objects import ObjectRules, Objects, discriminate
from torchsar_eval.coco import CocoExport

MAPS = {
    "sharpen": lambda s: 1.0 - 1e-12 * (2.0 - s),  # scores within 1e-12 of 1
    "stretch": lambda s: 10.0 ** (8.0 * s),  # past 1e6 and below 1e-6
    "affine": lambda s: 3.0 * s - 10.0,  # onto negative numbers
    "logit": lambda s: np.log(s / (2.0 - s)),
}
"""Strictly increasing maps of scores in (0, 2) that keep 1/64 steps distinct in float64."""


def _scene(rng, n_img=3, size=48, ties=False):
    """Random instances, an ignore patch, and non-touching detection rectangles whose peak
    scores are distinct (or, with ``ties``, drawn from four levels)."""
    inst = np.zeros((n_img, size, size), int)
    ignore = np.zeros((n_img, size, size), bool)
    stat = np.zeros((n_img, size, size))
    levels_ = rng.permutation(np.arange(33, 120)) / 64.0  # in (0.5, 2), 1/64 apart
    k = 0
    for p in range(n_img):
        for i in range(1, rng.integers(0, 5) + 1):
            r, c = rng.integers(0, size - 10, 2)
            inst[p, r : r + rng.integers(3, 10), c : c + rng.integers(3, 10)] = i
        if rng.random() < 0.5:
            r, c = rng.integers(0, size - 8, 2)
            ignore[p, r : r + 6, c : c + 6] = True
        for cell in range(36):
            if rng.random() < 0.25:
                r0, c0 = 8 * (cell // 6), 8 * (cell % 6)
                h, w = rng.integers(1, 7, 2)
                level = 0.5 + rng.integers(1, 5) / 4 if ties else levels_[k]
                stat[p, r0 + 1 : r0 + 1 + h, c0 + 1 : c0 + 1 + w] = level
                k += 1
    return inst, ignore, stat


def _objects(stat):
    return discriminate(torch.as_tensor(stat)[:, None], 1.0, rules=ObjectRules(floor=0.5))


def _state(inst, ignore, stat, rule, planes=None, replicates=0, obj=None):
    sel = slice(None) if planes is None else planes
    obj = _objects(stat[sel]) if obj is None else obj
    gt = ground_truth(inst[sel], ignore[sel])
    idx = np.arange(len(inst))[sel]
    st_ = ObjectState(replicates=replicates)
    st_.update(match_batch(obj, gt, rule), obj, gt, [ImageInfo(f"i{j}", order=int(j)) for j in idx])
    return st_, obj


def _pycocotools(inst, ignore, obj, iou_type):
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    batch = {
        "instances": torch.as_tensor(inst)[:, None],
        "ignore": torch.as_tensor(ignore)[:, None],
        "meta": [{"name": str(i)} for i in range(len(inst))],
    }
    ex = CocoExport("t")
    ex.add(batch, {"d": obj})
    ex._category("target")
    with contextlib.redirect_stdout(io.StringIO()):
        gt = COCO()
        gt.dataset = {
            "images": ex.images,
            "annotations": ex.annotations,
            "categories": [{"id": 1, "name": "target"}],
        }
        gt.createIndex()
        dt = gt.loadRes(ex.results["d"])
        ev = COCOeval(gt, dt, iou_type)
        ev.params.useCats = 0
        ev.params.maxDets = [1, 10, 100_000]
        ev.evaluate()
        ev.accumulate()
    prec = ev.eval["precision"][:, :, 0, 0, -1]  # (IoU, recall points)

    def ap(p):
        return float(p[p > -1].mean()) if (p > -1).any() else float("nan")

    return ap(prec[0]), float(np.mean([ap(p) for p in prec]))


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 100_000), iou_type=st.sampled_from(["segm", "bbox"]), ties=st.booleans())
def test_ap_equals_pycocotools(seed, iou_type, ties):
    inst, ignore, stat = _scene(np.random.default_rng(seed), ties=ties)
    rule = Matching(kind="mask" if iou_type == "segm" else "box")
    state, obj = _state(inst, ignore, stat, rule)
    if state.n_gt == 0 or len(obj) == 0:
        return  # pycocotools has nothing to score
    ap50, ap = _pycocotools(inst, ignore, obj, iou_type)
    m = state.metrics()
    assert m["ap50"] == pytest.approx(ap50, abs=1e-12)
    assert m["ap50_95"] == pytest.approx(ap, abs=1e-12)


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 100_000), cut=st.integers(0, 4), kind=st.sampled_from(["mask", "centroid"])
)
def test_merged_shards_equal_one_pass_in_any_order(seed, cut, kind):
    inst, ignore, stat = _scene(np.random.default_rng(seed), n_img=4, ties=seed % 2 == 0)
    rule = Matching(kind=kind)
    whole, _ = _state(inst, ignore, stat, rule, replicates=20)
    a, _ = _state(inst, ignore, stat, rule, slice(0, cut), replicates=20)
    b, _ = _state(inst, ignore, stat, rule, slice(cut, 4), replicates=20)
    for merged in (a + b, b + a):
        assert merged == whole
        assert merged.metrics() == pytest.approx(whole.metrics(), nan_ok=True, abs=0)
        for k, v in whole.replicate_metrics().items():
            np.testing.assert_array_equal(merged.replicate_metrics()[k], v)


def test_adding_an_image_twice_is_refused():
    inst, ignore, stat = _scene(np.random.default_rng(0), n_img=2)
    a, _ = _state(inst, ignore, stat, Matching("mask"))
    with pytest.raises(ValueError, match="added twice"):
        _ = (a + a).metrics()


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 100_000))
def test_breakdowns_sum_to_totals_and_froc_is_monotone(seed):
    inst, ignore, stat = _scene(np.random.default_rng(seed), n_img=4)
    state, _ = _state(inst, ignore, stat, Matching(kind="centroid"))
    m = state.metrics()
    keys = state.breakdown()
    for by in ("class", "size"):
        mine = [v for k, v in keys.items() if k.startswith(by + ":")]
        assert sum(k["n_gt"] for k in mine) == state.n_gt
        assert sum(k["tp"] for k in mine) == m["tp"]
        assert sum(k["fp"] for k in mine) == m["fp"]
    f = state.froc()
    assert np.all(np.diff(f["fa_per_image"]) >= 0) and np.all(np.diff(f["pd"]) >= 0)
    assert np.all(np.diff(f["threshold"]) < 0)  # one row per score level, highest first


def _records(state: ObjectState, m, obj, info) -> list[dict]:
    """The slow reference's view of a batch: one dict per detection."""
    code = {0: "fp", 1: "tp", 2: "ig"}
    op = np.where(m.op >= 0, 1, np.where(m.op == -2, 2, 0))
    ap = np.where(m.ap[0, 0] >= 0, 1, np.where(m.ap[0, 0] == -2, 2, 0))
    rank = {}
    out = []
    for k in range(len(obj)):
        p = int(obj.plane[k])
        rank[p] = rank.get(p, -1) + 1
        out.append(
            {
                "score": float(obj.score[k]),
                "order": info[p].order,
                "rank": rank[p],
                "op": code[int(op[k])],
                "ap50": code[int(ap[k])],
            }
        )
    return out


def _data(seed, ties, n_img=5):
    inst, ignore, stat = _scene(np.random.default_rng(seed), n_img=n_img, ties=ties)
    obj = _objects(stat)
    obj = obj.with_threshold(1.3)
    gt = ground_truth(inst, ignore)
    rule = Matching("centroid")
    m = match_batch(obj, gt, rule)
    info = [ImageInfo(f"i{p}", order=10 * p + 3) for p in range(n_img)]
    return m, obj, gt, info


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 100_000),
    ties=st.booleans(),
    threshold=st.sampled_from(["design", None, 1.0, 1.6, 5.0]),
)
def test_metrics_equal_the_slow_reference(seed, ties, threshold):
    m, obj, gt, info = _data(seed, ties)
    state = ObjectState(replicates=0)
    state.update(m, obj, gt, info)
    got = state.metrics(threshold)
    thr = 1.3 if threshold == "design" else threshold
    want = ref.metrics(_records(state, m, obj, info), len(gt), len(info), thr)
    for k, v in want.items():
        assert got[k] == pytest.approx(v, abs=1e-12, nan_ok=True), k


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 100_000), ties=st.booleans())
def test_every_replicate_equals_the_slow_reference_on_the_resampled_images(seed, ties):
    """Replicate r is the dataset with image i drawn w_r(i) times: each of its detections
    repeated w_r(i) times in a row, its targets and the image counted w_r(i) times."""
    m, obj, gt, info = _data(seed, ties)
    state = ObjectState(replicates=12, seed=seed)
    state.update(m, obj, gt, info)
    got = state.replicate_metrics()
    w = poisson_weights([i.key for i in info], 12, seed)
    dets = _records(state, m, obj, info)
    n_gt = np.bincount(gt.plane, minlength=len(info))
    for r in range(12):
        weight = {i.order: int(w[r, p]) for p, i in enumerate(info)}
        want = ref.metrics(
            ref.expand(dets, weight.__getitem__),
            float(w[r] @ n_gt),
            float(w[r].sum()),
            1.3,
            expanded=True,
        )
        for k, v in want.items():
            assert got[k][r] == pytest.approx(v, abs=1e-12, nan_ok=True), (k, r)


def _mapped(obj: Objects, f) -> Objects:
    from dataclasses import replace

    return replace(obj, score=f(obj.score), threshold=float(f(np.float64(obj.threshold))))


def _image_under(obj: Objects, mapped: Objects, f):
    """The map as the mapped objects hold it: a score's own mapped value, else ``f``.

    NumPy's vectorised ``pow``/``log`` may round an array element one ulp away from the same
    value mapped alone, so a score is looked up rather than mapped again.
    """
    table = dict(zip(obj.score.tolist(), mapped.score.tolist(), strict=True))
    table[float(obj.threshold)] = mapped.threshold

    def image(values):
        values = np.asarray(values, dtype=np.float64)
        out = [table.get(v, float(f(np.float64(v)))) for v in values.ravel().tolist()]
        return np.asarray(out, dtype=np.float64).reshape(values.shape)

    return image


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 100_000), ties=st.booleans(), name=st.sampled_from(sorted(MAPS)))
def test_a_strictly_increasing_map_of_the_scores_changes_no_number(seed, ties, name):
    f = MAPS[name]
    m, obj, gt, info = _data(seed, ties)
    mapped = _mapped(obj, f)
    assert np.array_equal(
        np.argsort(-obj.score, kind="stable"), np.argsort(-mapped.score, kind="stable")
    )
    image = _image_under(obj, mapped, f)
    a, b = ObjectState(replicates=30), ObjectState(replicates=30)
    a.update(m, obj, gt, info)
    b.update(match_batch(mapped, gt, Matching("centroid")), mapped, gt, info)
    assert a.metrics() == pytest.approx(b.metrics(), nan_ok=True, abs=1e-12)
    for k, v in a.replicate_metrics().items():
        np.testing.assert_allclose(b.replicate_metrics()[k], v, rtol=0, atol=1e-12)
    ia, ib = a.intervals(), b.intervals()
    for k, v in ia.items():
        assert (v.lo, v.hi) == pytest.approx((ib[k].lo, ib[k].hi), nan_ok=True, abs=1e-12), k
    fa, fb = a.froc(), b.froc()
    np.testing.assert_array_equal(image(fa["threshold"]), fb["threshold"])
    for k in ("tp", "fp", "fa_per_image", "pd"):
        np.testing.assert_array_equal(fa[k], fb[k])
    for kind, level in (("f1", None), ("fa", 0.5), ("fa", 2.0)):
        ta, tb = a.choose_threshold(kind, level), b.choose_threshold(kind, level)
        assert (ta is None and tb is None) or image(ta) == tb
        assert a.metrics(ta) == pytest.approx(b.metrics(tb), nan_ok=True, abs=1e-12)


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 100_000),
    ties=st.booleans(),
    n_img=st.integers(1, 8),
    threshold=st.sampled_from(["design", None, 1.0, 1.6]),
)
def test_every_interval_contains_its_point(seed, ties, n_img, threshold):
    m, obj, gt, info = _data(seed, ties, n_img)
    state = ObjectState(replicates=50, seed=seed)
    state.update(m, obj, gt, info)
    point = state.metrics(threshold)
    for k, iv in state.intervals(threshold).items():
        name = {"fa_per_image": "fa_per_image"}.get(k, k)
        if math.isfinite(iv.lo) and math.isfinite(iv.hi):
            assert iv.lo <= point[name] <= iv.hi, (k, iv, point[name])


def test_curve_helpers_by_hand():
    # ranked TP, FP, TP on 2 images with 2 targets: FROC (0, 0), (0, .5), (.5, .5), (.5, 1)
    fa, pd = np.array([0.0, 0.0, 0.5, 0.5]), np.array([0.0, 0.5, 0.5, 1.0])
    assert pd_at_fa(fa, pd, 0.1) == 0.5 and pd_at_fa(fa, pd, 0.5) == 1.0
    assert partial_auc(fa, pd, 1.0) == pytest.approx(0.5 * 0.5 + 1.0 * 0.5)
    assert coco_ap(np.array([1, 0, 1]), np.array([0, 1, 0]), 2) == pytest.approx(
        (51 + 50 * 2 / 3) / 101
    )
    assert np.isnan(coco_ap(np.array([1]), np.array([0]), 0))
    assert levels(np.array([3.0, 3.0, 2.0, 1.0, 1.0])).tolist() == [1, 2, 4]


def test_choose_threshold_by_hand():
    """Two images, two targets; ranked TP 0.9, FP 0.8, FP 0.8, TP 0.5."""
    from torchsar.metrics.assign import BatchMatch

    score = np.array([0.9, 0.8, 0.8, 0.5])
    obj = Objects.from_points(
        np.zeros((4, 2)), score, shape=(8, 8), plane=np.array([0, 0, 1, 1]), planes=2
    )
    inst = np.zeros((2, 8, 8), int)
    inst[0, 0, 0] = inst[1, 4, 4] = 1
    gt = ground_truth(inst)
    op = np.array([0, -1, -1, 1])
    m = BatchMatch(
        np.tile(op, (4, 10, 1)),
        op,
        np.zeros(4),
        np.array([0.9, 0.5]),
        np.zeros(2, np.int64),
        np.array([0, 3]),
        "iou",
    )
    state = ObjectState(replicates=0)
    state.update(m, obj, gt, [ImageInfo("a", order=0), ImageInfo("b", order=1)])
    assert state.choose_threshold("fa", 0.0) == 0.8  # only the top TP
    assert state.choose_threshold("fa", 0.99) == 0.8  # the tied false alarms come together
    assert state.choose_threshold("fa", 1.0) is None  # everything
    assert state.choose_threshold("f1") == 0.8  # F1 2/3 at the top TP, tie with all: fewer
    assert state.metrics(0.8)["tp"] == 1 and state.metrics(None)["tp"] == 2


@pytest.mark.parametrize("kind", ["centroid", "mask"])
def test_all_true_and_all_false_masks_on_simulated_data(kind):
    import torchsar as ts
    from torchsar_eval.detector import Detector
    from torchsar_eval.result import Scoring
    from torchsar_eval.runner import run_detectors

    def constant(value):
        return lambda x: ts.cfar.detection_from(torch.full_like(x, value), 1.0)

    specs = [Detector("all_true", constant(2.0)), Detector("all_false", constant(0.0))]
    scoring = Scoring(ObjectRules(closing=2, min_area=5), Matching(kind=kind), 0)
    for n, sim in ((8, ts.simulate.chips), (2, ts.simulate.scenes)):
        b = sim(n, seed=1)
        ds = [{**b[i], "meta": {"name": str(i), **b[i]["meta"]}} for i in range(n)]
        yes, no = (
            r.objects.metrics() for r in run_detectors(ds, specs, scoring=scoring, progress=False)
        )
        assert yes["tp"] == 0 and yes["fp"] == n and yes["recall"] == 0  # one flood per image
        assert yes["ap50"] == 0 and yes["pd_at_1_fa_per_image"] == 0
        assert no["tp"] == no["fp"] == 0 and np.isnan(no["precision"]) and no["recall"] == 0


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 100_000), rows=st.integers(1, 6), n_gt=st.integers(0, 9))
def test_ap_of_many_rows_equals_ap_row_by_row(seed, rows, n_gt):
    rng = np.random.default_rng(seed)
    status = rng.integers(0, 3, 40)  # 0 fp, 1 tp, 2 ignored
    w = rng.poisson(1.0, (rows, 40))
    tp, fp = w * (status == 1), w * (status == 0)
    gts = rng.integers(0, n_gt + 1, rows)
    got = coco_ap_rows(tp, fp, gts)
    for r in range(rows):
        statuses = [s for k in range(40) for s in [("fp", "tp", "ig")[status[k]]] * int(w[r, k])]
        want = ref.coco_ap(statuses, gts[r])
        assert got[r] == pytest.approx(want, abs=1e-12, nan_ok=True)


def test_weights_depend_on_the_unit_and_seed_only():
    w = poisson_weights(["a", "b", "c"], 200, seed=4)
    again = poisson_weights(np.array([unit_hash(k) for k in ("c", "a")], np.uint64), 200, seed=4)
    np.testing.assert_array_equal(w[:, [2, 0]], again)
    assert not np.array_equal(w, poisson_weights(["a", "b", "c"], 200, seed=5))
    big = poisson_weights([str(i) for i in range(5000)], 40, seed=0).astype(float)
    assert abs(big.mean() - 1) < 0.01 and abs(big.var() - 1) < 0.02  # Poisson(1)


def test_ap_rows_read_the_recall_points_exactly():
    """7 of 20 targets is a recall of 0.35, short of COCO's recall point 0.35000000000000003
    (``np.linspace(0, 1, 101)[35]``): no precision there, in one row or in many."""
    tp = np.zeros((2, 12))
    tp[:, :7] = 1  # 7 true positives then 5 false ones, twice
    fp = 1 - tp
    rows = coco_ap_rows(tp * np.array([[1], [2]]), fp * np.array([[1], [2]]), np.array([20, 40]))
    assert rows.tolist() == pytest.approx([35 / 101, 35 / 101], abs=1e-15)
    assert coco_ap(tp[0], fp[0], 20) == pytest.approx(35 / 101, abs=1e-15)
