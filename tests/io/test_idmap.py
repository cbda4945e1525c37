"""Instance-id maps decoded colour -> id, never averaged."""

from __future__ import annotations

import numpy as np
import pytest

from torchsar.io import FileFormatError, decode_id_map


def test_colours_with_equal_grey_mean_stay_apart():
    m = np.zeros((3, 4, 3), np.uint8)
    m[0, 0:2] = (90, 0, 0)  # mean 30
    m[2, 3] = (0, 0, 90)  # mean 30 too
    m[1, 1] = (0, 90, 0)
    ids = decode_id_map(m, "ids.png")
    expected = np.array([[1, 1, 0, 0], [0, 2, 0, 0], [0, 0, 0, 3]])
    np.testing.assert_array_equal(ids, expected)
    assert ids.dtype == np.int32


def test_grey_ids_are_renumbered_in_order_of_appearance():
    ids = decode_id_map(np.array([[0, 7, 7], [3, 0, 9]]), "ids.png")
    np.testing.assert_array_equal(ids, [[0, 1, 1], [2, 0, 3]])


def test_alpha_is_ignored_and_no_background_is_fine():
    m = np.dstack([np.full((2, 2), 5), np.zeros((2, 2)), np.zeros((2, 2)), np.full((2, 2), 255)])
    np.testing.assert_array_equal(decode_id_map(m.astype(np.uint8), "a.png"), np.ones((2, 2)))


def test_lossy_id_map_is_refused():
    with pytest.raises(FileFormatError, match="ids.jpeg: is a JPEG"):
        decode_id_map(np.zeros((2, 2, 3), np.uint8), "ids.jpeg")
