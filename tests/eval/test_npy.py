from __future__ import annotations

import io

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from torchsar_eval.npy import read_npy


def _npy(a: np.ndarray, version=None) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, a, version=version, allow_pickle=False)
    return buf.getvalue()


@settings(max_examples=60, deadline=None)
@given(
    shape=st.lists(st.integers(0, 5), min_size=0, max_size=4),
    dtype=st.sampled_from(["<f4", ">f8", "<i8", "|b1", "<u2", "<c8", "|u1"]),
    fortran=st.booleans(),
    version=st.sampled_from([(1, 0), (2, 0), (3, 0)]),
    seed=st.integers(0, 1000),
)
def test_equals_numpy_load(shape, dtype, fortran, version, seed):
    a = (np.random.default_rng(seed).random(shape) * 100).astype(dtype)
    a = np.asfortranarray(a) if fortran else a
    data = _npy(a, version)
    got = read_npy(data)
    ref = np.load(io.BytesIO(data), allow_pickle=False)
    assert got.dtype == ref.dtype and got.shape == ref.shape and np.array_equal(got, ref)
    assert got.flags.writeable


def test_bad_bytes_are_refused():
    data = _npy(np.arange(10.0))
    with pytest.raises(ValueError, match="not .npy"):
        read_npy(b"PK" + data[2:])
    with pytest.raises(ValueError, match="truncated"):
        read_npy(data[:-8])
    with pytest.raises(ValueError, match="object"):
        read_npy(data.replace(b"'<f8'", b"'|O' "))  # the same header, an object dtype
