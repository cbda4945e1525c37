"""Full-image overlays (``--overlay``): the drawn outlines sit where the objects are (read
back from the palette indices), the counts beside each picture are the run's own per-image
counts at its reported operating point (calibrated too), names are checked before the run."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch
from PIL import Image
from scipy import ndimage

import torchsar_eval as te
from torchsar.metrics import Matching, match_batch
from torchsar.metrics.truth import ground_truth
from torchsar.objects import Objects
from torchsar_eval.cli import main
from torchsar_eval.errors import EvalError
from torchsar_eval.overlays import (
    FALSE_ALARM,
    FOUND,
    HIT,
    MAX_SIDE,
    MISSED,
    parse_overlay,
    render_overlay,
)


def _ring(mask: np.ndarray, width: int) -> np.ndarray:
    """The reference band: ``width`` 8-connected dilations of the mask, less the mask."""
    grown = ndimage.binary_dilation(mask, np.ones((3, 3), bool), iterations=width)
    return grown & ~mask


def test_outlines_sit_on_the_objects_they_draw():
    """Two mask targets (one found, one missed), a mask hit and a mask false alarm on a
    600 x 600 plane (drawn at its own size): each colour is exactly its objects' ring."""
    h = w = 600
    inst = np.zeros((1, h, w), np.int64)
    inst[0, 100:120, 100:130] = 1  # found
    inst[0, 400:430, 300:310] = 2  # missed
    gt = ground_truth(inst)
    labels = np.zeros((1, h, w), np.int32)
    labels[0, 102:118, 104:126] = 1  # hits target 1
    labels[0, 250:260, 500:520] = 2  # false alarm
    obj = Objects.from_labels(labels, np.where(labels == 1, 5.0, 4.0), threshold=1.0)
    m = match_batch(obj, gt, Matching(kind="mask", iou=0.3))
    assert m.op.tolist() == [0, -1]
    image = torch.rand(1, 1, h, w, generator=torch.Generator().manual_seed(0)) + 0.1
    px, counts = render_overlay(image, 0, obj, gt, m.op)
    assert px.shape == (h, w)
    assert counts == {"targets": 2, "found": 1, "missed": 1, "hits": 1, "false_alarms": 1}
    np.testing.assert_array_equal(px == MISSED, _ring(inst[0] == 2, 2))
    np.testing.assert_array_equal(px == FALSE_ALARM, _ring(labels[0] == 2, 1))
    # the hit lies inside the found target: its ring is drawn over the target's pixels
    np.testing.assert_array_equal(px == HIT, _ring(labels[0] == 1, 1))
    np.testing.assert_array_equal(px == FOUND, _ring(inst[0] == 1, 1) & ~(px == HIT))


def test_boxes_small_images_doubled_and_large_ones_reduced():
    gt = ground_truth(np.zeros((1, 40, 40), np.int64))
    obj = Objects.from_boxes(
        [np.array([[10.0, 12.0, 20.0, 30.0]])], [np.array([0.9])], shape=(40, 40), threshold=0.5
    )
    px, counts = render_overlay(None, 0, obj, gt, np.array([-1]))
    assert px.shape == (80, 80) and counts["false_alarms"] == 1
    rows, cols = np.nonzero(px == FALSE_ALARM)  # a frame of one image pixel just outside it
    assert (rows.min(), rows.max(), cols.min(), cols.max()) == (18, 41, 22, 61)
    assert not (px[20:40, 24:60] == FALSE_ALARM).any()
    below = Objects.from_boxes(
        [np.array([[1.0, 1, 5, 5]])], [np.array([0.2])], shape=(40, 40), threshold=0.5
    )
    px, counts = render_overlay(None, 0, below, gt, np.array([-1]))
    assert counts["false_alarms"] == 0 and not (px == FALSE_ALARM).any()  # below the threshold
    big = ground_truth(np.zeros((1, 2 * MAX_SIDE + 2, 64), np.int64))
    none = Objects.from_boxes([np.zeros((0, 4))], [np.zeros(0)], shape=(2 * MAX_SIDE + 2, 64))
    px, _ = render_overlay(torch.ones(1, 1, 2 * MAX_SIDE + 2, 64), 0, none, big, np.zeros(0, int))
    assert px.shape == (1366, 22)  # 4098 rows over 2048: block-averaged by 3


@pytest.mark.figures
def test_counts_equal_the_run_per_image_rows(tmp_path):
    out = tmp_path / "run"
    assert (
        main(
            [
                "run",
                "--dataset",
                "sim-chips",
                "--n",
                "8",
                "--detectors",
                "ca,os,region",
                "--overlay",
                "3",
                "--no-progress",
                "--bootstrap",
                "0",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    drawn = pd.read_csv(out / "overlays" / "overlays.csv")
    rows = pd.read_csv(out / "per_image.csv")
    summary = pd.read_csv(out / "summary.csv").set_index("detector")
    assert len(drawn) == 9 and drawn["image"].tolist()[:3] == ["sim-chips/0"] * 3
    for _, d in drawn.iterrows():
        r = rows[(rows.detector == d.detector) & (rows.image == d.image)].iloc[0]
        assert (d.targets, d.found, d.hits, d.false_alarms) == (r.targets, r.tp, r.tp, r.fp)
        assert d.threshold == summary.loc[d.detector, "score_threshold"]
        png = Image.open(out / d.file)
        assert png.size == (256, 256)  # 128 x 128 chips drawn at twice their size
    html = (out / "report.html").read_text()
    assert "Whole images" in html and html.count('class="overlay"') == 9


def test_a_calibrated_run_is_drawn_at_its_chosen_threshold(tmp_path):
    """Every image of the test split drawn: the overlays' counts add up to the summary's
    (which is at the chosen threshold, not the design one)."""
    out = tmp_path / "run"
    assert (
        main(
            [
                "run",
                "--dataset",
                "sim-chips",
                "--n",
                "16",
                "--detectors",
                "ca,os",
                "--calibrate-on",
                "f1",
                "--overlay",
                "16",
                "--no-progress",
                "--bootstrap",
                "0",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    drawn = pd.read_csv(out / "overlays" / "overlays.csv")
    summary = pd.read_csv(out / "summary.csv").set_index("detector")
    for det, d in drawn.groupby("detector"):
        s = summary.loc[det]
        assert len(d) == s["images"] < 16
        assert (d.found.sum(), d.false_alarms.sum()) == (s["tp"], s["false_alarms"])
        assert (d.threshold == s["score_threshold"]).all()


def test_names_are_checked_before_the_run_and_need_a_folder(tmp_path):
    with pytest.raises(EvalError, match="has no image 'nope'"):
        te.evaluate(
            "sim-chips",
            ["ca"],
            n=4,
            overlay=["sim-chips/1", "nope"],
            out=tmp_path / "x",
            progress=False,
        )
    assert not list((tmp_path).glob("**/shard-*"))
    with pytest.raises(EvalError, match="overlay.*needs.*out"):
        te.evaluate("sim-chips", ["ca"], n=4, overlay=2, progress=False)
    assert parse_overlay("0") is None and parse_overlay(["a.png", "b.png,c"]) == (
        "a.png",
        "b.png",
        "c",
    )
    with pytest.raises(EvalError, match="from 0 to"):
        parse_overlay(1000)


def test_the_report_copy_is_drawn_small_and_linked(tmp_path):
    """A 600 x 600 image: the full picture and a copy drawn at half size (its outlines
    drawn on the small grid, not resampled), both written; the copy is what the report
    embeds, linked to the full one."""
    from torchsar_eval.overlays import REPORT_SIDE, Overlay, write_overlays

    inst = np.zeros((1, 600, 600), np.int64)
    inst[0, 100:140, 200:260] = 1
    gt = ground_truth(inst)
    none = Objects.from_boxes([np.zeros((0, 4))], [np.zeros(0)], shape=(600, 600))
    full, counts = render_overlay(None, 0, none, gt, np.zeros(0, int))
    small, _ = render_overlay(None, 0, none, gt, np.zeros(0, int), max_side=REPORT_SIDE)
    assert full.shape == (600, 600) and small.shape == (300, 300)
    rows, cols = np.nonzero(small == MISSED)
    assert (rows.min(), rows.max(), cols.min(), cols.max()) == (48, 71, 98, 131)
    o = Overlay("d", "ca", "a/b.png", 0, full, counts, 1.0, small)
    assert write_overlays(tmp_path, {"d": [o]}, {"d": "d"}) == ["overlays/"]
    table = pd.read_csv(tmp_path / "overlays" / "overlays.csv")
    assert table.file[0] == "overlays/d/ca/b.png" and table.small[0] == "overlays/d/ca/b-small.png"
    assert Image.open(tmp_path / table.small[0]).size == (300, 300)
