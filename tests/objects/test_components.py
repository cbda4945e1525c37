from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from torchsar.objects import label_components


def _reference(mask: np.ndarray, connectivity: int) -> tuple[np.ndarray, int]:
    """scipy's n-D labelling with a structure that connects within a plane only."""
    structure = np.zeros((3,) * (mask.ndim - 2) + (3, 3), bool)
    structure[(1,) * (mask.ndim - 2)] = ndimage.generate_binary_structure(2, connectivity)
    return ndimage.label(mask, structure=structure)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    shape=st.sampled_from([(7, 9), (3, 6, 5), (2, 2, 4, 11), (4, 1, 13), (5, 12, 1)]),
    density=st.floats(0.05, 0.8),
    connectivity=st.sampled_from([1, 2]),
)
def test_labels_equal_scipy_with_planes_kept_apart(seed, shape, density, connectivity):
    mask = np.random.default_rng(seed).random(shape) < density
    labels, n = label_components(mask, connectivity)
    ref, n_ref = _reference(mask, connectivity)
    assert n == n_ref and labels.dtype == np.int32 and np.array_equal(labels, ref)
