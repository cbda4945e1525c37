"""COCO run lengths decoded straight to pixels equal pycocotools' dense decoding."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pycocotools import mask as mask_utils

from torchsar.io.coco import CocoAnnotation, annotation_pixels
from torchsar.io.rle import counts_from_strings, rle_pixels


def _masks(rng, h, w, n, kind):
    if kind == "noise":
        return rng.random((h, w, n)) < rng.random()
    m = np.zeros((h, w, n), bool)
    for k in range(n):
        if kind == "full" and k % 2:
            m[..., k] = True
            continue
        a, b = np.sort(rng.integers(0, h, 2))
        c, d = np.sort(rng.integers(0, w, 2))
        m[a : b + 1, c : d + 1, k] = kind != "empty"
    return m


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    h=st.integers(1, 90),
    w=st.integers(1, 90),
    n=st.integers(1, 6),
    kind=st.sampled_from(["noise", "boxes", "empty", "full"]),
)
def test_pixels_equal_dense_decoding(seed, h, w, n, kind):
    rng = np.random.default_rng(seed)
    masks = np.asfortranarray(_masks(rng, h, w, n, kind).astype(np.uint8))
    rles = mask_utils.encode(masks)
    counts, owner = counts_from_strings([r["counts"] for r in rles])
    mask_of, flat = rle_pixels(counts, owner, n, (h, w))
    for k in range(n):
        assert np.array_equal(np.sort(flat[mask_of == k]), np.flatnonzero(masks[..., k]))


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # pycocotools.decode under numpy 2
def test_large_counts_and_polygons():
    """Counts of many 5-bit groups (a 3000 x 3000 mask), and polygons through frPyObjects."""
    m = np.zeros((3000, 3000), np.uint8, order="F")
    m[2000:2003, 2500:2990] = 1
    counts, owner = counts_from_strings([mask_utils.encode(m)["counts"]])
    _, flat = rle_pixels(counts, owner, 1, m.shape)
    assert np.array_equal(np.sort(flat), np.flatnonzero(m))
    poly = CocoAnnotation(1, "ship", (1.0, 2.0, 4.0, 6.0), [[2, 1, 6, 1, 6, 4, 2, 4]], False)
    box = CocoAnnotation(2, "ship", (1.0, 2.0, 3.0, 5.0), None, False)
    a, b = annotation_pixels([poly, box], 8, 10)
    dense = mask_utils.decode(mask_utils.merge(mask_utils.frPyObjects(poly.segmentation, 8, 10)))
    assert np.array_equal(np.sort(a), np.flatnonzero(dense))
    assert b.tolist() == [12, 13, 14, 22, 23, 24]


def test_no_strings():
    counts, owner = counts_from_strings([])
    assert counts.size == 0 and rle_pixels(counts, owner, 0, (4, 4))[1].size == 0
