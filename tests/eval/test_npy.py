from __future__ import annotations

import io

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from torchsar_eval.npy import NpyError, read_npy


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


def _with_header(text: str) -> bytes:
    """``.npy`` bytes (version 1) whose header dict is ``text``, padded as numpy pads it."""
    head = text.encode("latin1")
    head += b" " * (-(10 + len(head) + 1) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + len(head).to_bytes(2, "little") + head


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"\x93NUM", "not .npy bytes"),
        (b"\x93NUMPY\x01\x00\xff\xff{", "truncated or oversized .npy header"),
        (_with_header("{'descr': '<f8', 'fortran_order': False, 'shape': (2,), "), "unreadable"),
        (_with_header("[" * 5000), "unreadable"),
        (_with_header("(1, 2)"), "must be a dict"),
        (_with_header("{'descr': '<f8', 'fortran_order': False, 'shape': (-1,), }"), "shape"),
        (_with_header("{'descr': '<f8', 'fortran_order': False, 'shape': (2.5,), }"), "shape"),
        (_with_header("{'descr': '<f8', 'fortran_order': 0, 'shape': (), }"), "fortran_order"),
        (
            _with_header("{'descr': [('a', '<f8')], 'fortran_order': False, 'shape': (), }"),
            "not a plain number",
        ),
        (
            _with_header("{'descr': '<M8[s]', 'fortran_order': False, 'shape': (), }"),
            "not a plain number",
        ),
        (
            _with_header("{'descr': 'x', 'fortran_order': False, 'shape': (), }"),
            "not a plain number",
        ),
        (_npy(np.arange(4.0)) + b"\0" * 8, "oversized .npy data"),
        (
            _with_header(
                "{'descr': '<f8', 'fortran_order': False, 'shape': (1099511627776, 1099511627776), }"
            ),
            "truncated .npy data",
        ),
    ],
)
def test_bad_headers_are_one_value_error(data, message):
    with pytest.raises(NpyError, match=message):
        read_npy(data)
