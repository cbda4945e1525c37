"""to_intensity: each declared sample type against its textbook definition."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from torchsar.errors import InputTypeError, InputValueError, OptionError
from torchsar.io import SAMPLE_TYPES, to_intensity

finite = st.floats(0, 1e6, allow_nan=False, width=32)


@given(arrays(np.float32, (3, 4), elements=finite))
def test_each_type_matches_its_definition(a):
    np.testing.assert_allclose(to_intensity(a, "intensity"), a, rtol=1e-6)
    np.testing.assert_allclose(
        to_intensity(a, "amplitude"), a.astype(float) ** 2, rtol=1e-6, atol=1e-30
    )
    db = np.log10(a.astype(float) + 1.0)  # any real dB values
    np.testing.assert_allclose(to_intensity(db, "db"), 10 ** (db / 10), rtol=1e-6)
    z = a + 1j * a[::-1]
    np.testing.assert_allclose(to_intensity(z, "complex"), np.abs(z) ** 2, rtol=1e-5, atol=1e-30)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_display_integers_scale_by_dtype_max_then_square(dtype):
    top = np.iinfo(dtype).max
    out = to_intensity(np.array([0, top // 2, top], dtype), "display")
    np.testing.assert_allclose(out, [0.0, (top // 2 / top) ** 2, 1.0], rtol=1e-6)
    assert out.dtype == np.float32


def test_errors_name_the_problem():
    with pytest.raises(OptionError, match="sample_type must be one of"):
        to_intensity(np.ones(2), "linear")
    with pytest.raises(InputTypeError, match="must not be complex"):
        to_intensity(np.ones(2, complex), "amplitude")
    with pytest.raises(InputTypeError, match="must not be real"):
        to_intensity(np.ones(2), "complex")
    with pytest.raises(InputValueError, match="NaN or Inf"):
        to_intensity(np.array([1.0, np.nan]), "amplitude")
    with pytest.raises(InputValueError, match=">= 0"):
        to_intensity(np.array([-1.0]), "intensity")
    assert set(SAMPLE_TYPES) == {"intensity", "amplitude", "db", "complex", "display"}
