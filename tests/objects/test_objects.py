"""Objects' public constructors: masks (overlapping allowed), pixel lists, labels, boxes in
three formats, points, torchvision outputs; their properties against regionprops and by
construction; bad input named."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from skimage.measure import regionprops

from torchsar.errors import InputValueError, OptionError, ShapeError
from torchsar.objects import Objects


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(0, 6))
def test_masks_measure_like_regionprops_and_may_overlap(seed, n):
    rng = np.random.default_rng(seed)
    masks = rng.random((n, 12, 14)) < rng.uniform(0.05, 0.5, (n, 1, 1))
    masks[:, 0, 0] = True  # no empty mask
    scores = rng.random(n)
    plane = rng.integers(0, 3, n)
    o = Objects.from_masks(masks, scores, plane=plane, planes=3)
    assert (len(o), o.planes, o.shape, o.geometry, o.labels) == (n, 3, (12, 14), "mask", None)
    for k in range(n):
        (r,) = regionprops(masks[k].astype(np.uint8))
        assert o.area[k] == r.area and o.box[k].tolist() == list(r.bbox)
        np.testing.assert_allclose(o.centroid[k], r.centroid, atol=1e-9)
        np.testing.assert_allclose(
            [o.length[k], o.width[k]], [r.axis_major_length, r.axis_minor_length], atol=1e-6
        )
        assert np.array_equal(o.mask_of(k), masks[k]) and o.plane[k] == plane[k]
    assert np.array_equal(o.score, scores)


def test_per_plane_lists_equal_flat_arrays():
    boxes = [
        np.array([[1, 2, 5, 6.0]]),
        np.zeros((0, 4)),
        np.array([[0, 0, 3, 3.0], [2, 2, 4, 8.0]]),
    ]
    scores = [np.array([0.5]), np.zeros(0), np.array([0.9, 0.1])]
    a = Objects.from_boxes(boxes, scores, shape=(10, 10))
    b = Objects.from_boxes(
        np.concatenate(boxes),
        np.concatenate(scores),
        shape=(10, 10),
        plane=np.array([0, 2, 2]),
        planes=3,
    )
    for field in ("plane", "score", "box", "area", "centroid"):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field
    assert a.planes == b.planes == 3


def test_box_formats_agree():
    rc = Objects.from_boxes(np.array([[2.0, 1.0, 6.0, 4.0]]), np.array([1.0]), shape=(8, 8))
    xyxy = Objects.from_boxes(
        np.array([[1.0, 2.0, 4.0, 6.0]]), np.array([1.0]), shape=(8, 8), box_format="xyxy"
    )
    xywh = Objects.from_boxes(
        np.array([[1.0, 2.0, 3.0, 4.0]]), np.array([1.0]), shape=(8, 8), box_format="xywh"
    )
    for o in (xyxy, xywh):
        assert np.array_equal(o.box, rc.box) and np.array_equal(o.centroid, rc.centroid)
    assert rc.area.tolist() == [12] and (rc.length[0], rc.width[0]) == (4.0, 3.0)


def test_labels_pixels_and_masks_give_the_same_objects():
    lab = np.zeros((2, 6, 6), int)
    lab[0, 1:3, 1:4] = 5
    lab[1, 4:, :2] = 2
    smap = np.arange(72.0).reshape(2, 6, 6)
    a = Objects.from_labels(lab, smap)
    masks = np.stack([lab[0] == 5, lab[1] == 2])
    b = Objects.from_masks(masks, a.score, plane=np.array([0, 1]), planes=2, threshold=1.0)
    c = Objects.from_pixel_lists(
        [np.flatnonzero(m) for m in masks],
        a.score,
        shape=(6, 6),
        plane=np.array([0, 1]),
        planes=2,
        threshold=1.0,
    )
    for o in (b, c):
        for field in ("plane", "area", "box", "centroid", "length", "width", "score"):
            np.testing.assert_array_equal(getattr(o, field), getattr(a, field), field)
    assert a.score.tolist() == [15.0, 67.0]  # the best score map value over each object


def test_points_and_torchvision():
    p = Objects.from_points(
        [np.array([[3.0, 4.0]]), np.zeros((0, 2))],
        [np.array([0.7]), np.zeros(0)],
        shape=(8, 8),
        length_m=np.array([12.0]),
    )
    assert (p.geometry, p.planes, p.area.tolist(), p.length_m.tolist()) == ("point", 2, [0], [12.0])
    out = [
        {
            "boxes": torch.tensor([[1.0, 2.0, 3.0, 5.0]]),
            "scores": torch.tensor([0.5]),
            "labels": torch.tensor([2]),
            "masks": torch.zeros(1, 1, 8, 8).index_fill_(2, torch.tensor([2, 3]), 0.9),
        }
    ]
    t = Objects.from_torchvision(out, shape=(8, 8), threshold=0.3)
    assert (t.geometry, t.area.tolist(), t.classes.tolist(), t.threshold) == (
        "mask",
        [16],
        ["2"],
        0.3,
    )


@pytest.mark.parametrize(
    ("make", "error", "message"),
    [
        (
            lambda: Objects.from_boxes(np.zeros((1, 4)), np.array([np.nan]), shape=(4, 4)),
            InputValueError,
            "scores must not hold NaN",
        ),
        (
            lambda: Objects.from_boxes(np.array([[2, 2, 1, 3.0]]), np.ones(1), shape=(4, 4)),
            InputValueError,
            "r1 >= r0",
        ),
        (
            lambda: Objects.from_boxes(np.zeros((2, 3)), np.ones(2), shape=(4, 4)),
            ShapeError,
            "(M, 4)",
        ),
        (
            lambda: Objects.from_boxes(
                np.zeros((1, 4)), np.ones(1), shape=(4, 4), box_format="yolo"
            ),
            OptionError,
            "box_format",
        ),
        (
            lambda: Objects.from_boxes(
                np.zeros((1, 4)), np.ones(1), shape=(4, 4), plane=np.array([3]), planes=2
            ),
            OptionError,
            "planes=2",
        ),
        (
            lambda: Objects.from_points(np.array([[np.inf, 1.0]]), np.ones(1), shape=(4, 4)),
            InputValueError,
            "finite",
        ),
        (
            lambda: Objects.from_masks(np.zeros((2, 4, 4), bool), np.ones(3)),
            ShapeError,
            "one entry per score",
        ),
        (
            lambda: Objects.from_pixel_lists([np.array([16])], np.ones(1), shape=(4, 4)),
            InputValueError,
            "H*W=16",
        ),
        (
            lambda: Objects.from_labels(np.zeros((1, 4, 4)), np.zeros((1, 4, 4))),
            ShapeError,
            "integer array",
        ),
        (lambda: Objects.empty(1, (0, 4)), OptionError, "positive sides"),
        (lambda: Objects.empty(1, (4, 4)).with_threshold(float("nan")), OptionError, "NaN"),
    ],
)
def test_bad_input_is_named(make, error, message):
    with pytest.raises(error, match=message.replace("(", r"\(").replace(")", r"\)")):
        make()


def test_empty_objects_of_every_geometry():
    for geometry in ("mask", "box", "point"):
        o = Objects.empty(3, (5, 6), geometry=geometry)
        assert len(o) == 0 and o.planes == 3 and o.geometry == geometry
        assert o.pixel_lists()[0].size == 0
