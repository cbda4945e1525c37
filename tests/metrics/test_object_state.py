from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from torchsar.metrics import Matching, ObjectState, ground_truth, match_batch
from torchsar.metrics.curves import (
    OP_BIN,
    SCORE_GRID,
    coco_ap,
    coco_ap_rows,
    froc,
    partial_auc,
    pd_at_fa,
)
from torchsar.metrics.object_state import ImageInfo
from torchsar.objects import ObjectRules, discriminate
from torchsar_eval.coco import CocoExport


def _scene(rng, n_img=3, size=48):
    """Random instances, an ignore patch, and non-touching detection rectangles whose peak
    scores are distinct grid points (so pycocotools' ranking has no ties)."""
    inst = np.zeros((n_img, size, size), int)
    ignore = np.zeros((n_img, size, size), bool)
    stat = np.zeros((n_img, size, size))
    levels = rng.permutation(np.arange(OP_BIN - 40, OP_BIN + 240))
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
                stat[p, r0 + 1 : r0 + 1 + h, c0 + 1 : c0 + 1 + w] = SCORE_GRID[levels[k]]
                k += 1
    return inst, ignore, stat


def _state(inst, ignore, stat, rule, planes=None, replicates=0):
    sel = slice(None) if planes is None else planes
    s = torch.as_tensor(stat[sel])[:, None]
    obj = discriminate(s, 1.0, rules=ObjectRules(floor=0.5))
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
        gt.dataset = {"images": ex.images, "annotations": ex.annotations,
                      "categories": [{"id": 1, "name": "target"}]}  # fmt: skip
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
@given(seed=st.integers(0, 100_000), iou_type=st.sampled_from(["segm", "bbox"]))
def test_ap_equals_pycocotools(seed, iou_type):
    inst, ignore, stat = _scene(np.random.default_rng(seed))
    rule = Matching(kind="mask" if iou_type == "segm" else "box")
    state, obj = _state(inst, ignore, stat, rule)
    if state.n_gt == 0 or len(obj) == 0:
        return  # pycocotools has nothing to score
    ap50, ap = _pycocotools(inst, ignore, obj, iou_type)
    m = state.metrics()
    assert m["ap50"] == pytest.approx(ap50, abs=1e-6)
    assert m["ap50_95"] == pytest.approx(ap, abs=1e-6)


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 100_000), cut=st.integers(0, 4), kind=st.sampled_from(["mask", "centroid"])
)
def test_merged_shards_equal_one_pass(seed, cut, kind):
    inst, ignore, stat = _scene(np.random.default_rng(seed), n_img=4)
    rule = Matching(kind=kind)
    whole, _ = _state(inst, ignore, stat, rule, replicates=20)
    a, _ = _state(inst, ignore, stat, rule, slice(0, cut), replicates=20)
    b, _ = _state(inst, ignore, stat, rule, slice(cut, 4), replicates=20)
    merged = a + b
    assert merged == whole
    assert merged.metrics() == pytest.approx(whole.metrics(), nan_ok=True)


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 100_000))
def test_breakdowns_sum_to_totals_and_froc_is_monotone(seed):
    inst, ignore, stat = _scene(np.random.default_rng(seed), n_img=4)
    state, _ = _state(inst, ignore, stat, Matching(kind="centroid"))
    m = state.metrics(OP_BIN)
    for by in ("class", "size"):
        keys = [v for k, v in state.keys.items() if k.startswith(by + ":")]
        assert sum(k.n_gt for k in keys) == state.n_gt
        assert sum(int(k.tp[OP_BIN:].sum()) for k in keys) == m["tp"]
        assert sum(int(k.fp[OP_BIN:].sum()) for k in keys) == m["fp"]
    _, fa, pd = state.froc()
    assert np.all(np.diff(fa) >= 0) and np.all(np.diff(pd[np.isfinite(pd)]) >= 0)


def test_bootstrap_intervals_bracket_the_estimate():
    inst, ignore, stat = _scene(np.random.default_rng(3), n_img=6)
    state, _ = _state(inst, ignore, stat, Matching(kind="centroid"), replicates=200)
    m, ci = state.metrics(), state.intervals()
    for k in ("precision", "recall", "f1"):
        lo, hi = ci[k]
        assert lo <= m[k] <= hi


def test_curve_helpers_by_hand():
    tp = np.zeros(SCORE_GRID.size + 1, int)
    fp = np.zeros_like(tp)
    tp[300], fp[200], tp[100] = 1, 1, 1  # ranked TP, FP, TP; 2 images, 2 targets
    fa, pd = froc(tp, fp, 2, 2)
    assert pd_at_fa(fa, pd, 0.1) == 0.5 and pd_at_fa(fa, pd, 0.5) == 1.0
    assert partial_auc(fa, pd, 1.0) == pytest.approx(0.5 * 0.5 + 1.0 * 0.5)
    assert coco_ap(tp, fp, 2) == pytest.approx((51 + 50 * 2 / 3) / 101)
    assert np.isnan(coco_ap(tp, fp, 0))


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
        yes, no = (r.objects.metrics() for r in run_detectors(ds, specs, scoring=scoring,
                                                         progress=False))  # fmt: skip
        assert yes["tp"] == 0 and yes["fp"] == n and yes["recall"] == 0  # one flood per image
        assert yes["ap50"] == 0 and yes["pd_at_1_fa_per_image"] == 0
        assert no["tp"] == no["fp"] == 0 and np.isnan(no["precision"]) and no["recall"] == 0


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 100_000), rows=st.integers(1, 6), n_gt=st.integers(0, 9))
def test_ap_of_many_rows_equals_ap_row_by_row(seed, rows, n_gt):
    rng = np.random.default_rng(seed)
    tp = rng.poisson(0.05, (rows, SCORE_GRID.size + 1)) * (rng.random((rows, 1)) < 0.8)
    fp = rng.poisson(0.05, tp.shape)
    gts = rng.integers(0, n_gt + 1, rows)
    got = coco_ap_rows(tp, fp, gts)
    ref = [coco_ap(t, f, g) for t, f, g in zip(tp, fp, gts, strict=True)]
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)


def test_replicate_metrics_equal_the_scalar_helpers_replicate_by_replicate():
    """The vectorised replicate metrics behind the intervals equal each replicate's metrics
    computed one by one with the scalar helpers."""
    from torchsar.metrics.object_state import operating_point

    inst, ignore, stat = _scene(np.random.default_rng(11), n_img=6)
    state, _ = _state(inst, ignore, stat, Matching(kind="centroid"), replicates=50)
    b, at = state.boot, OP_BIN
    got = state.replicate_metrics()
    assert set(got) == {"precision", "recall", "f1", "fom", "fa_per_image", "ap50",
                        "pd_at_0.1_fa_per_image", "pd_at_1_fa_per_image",
                        "pd_at_10_fa_per_image", "pauc"}  # fmt: skip
    for r in range(50):
        n_gt, images = int(b["n_gt"][r]), int(b["images"][r])
        op = operating_point(b["tp"][r], b["fp"][r], n_gt, images, at)
        fa, pd = froc(b["tp"][r], b["fp"][r], n_gt, images)
        nan = float("nan")
        ref = {k: op[k] for k in ("precision", "recall", "f1")}
        ref["fom"] = op["tp"] / (op["fp"] + n_gt) if op["fp"] + n_gt else nan
        ref["fa_per_image"] = op["fa_per_image"]
        ref["ap50"] = coco_ap(b["tp50"][r], b["fp50"][r], n_gt)
        for level in (0.1, 1.0, 10.0):
            ref[f"pd_at_{level:g}_fa_per_image"] = pd_at_fa(fa, pd, level) if n_gt else nan
        ref["pauc"] = partial_auc(fa, pd, 1.0) if n_gt else nan
        for k, v in ref.items():
            assert got[k][r] == pytest.approx(v, abs=1e-12, nan_ok=True), (k, r)
