"""The fast JSON reader reads every document as the standard library's reader does."""

import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from torchsar.io import jsontext

_SCALARS = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**63), max_value=2**64 - 1)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=8)
)
_DOCUMENTS = st.recursive(
    _SCALARS,
    lambda inner: (
        st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=5), inner, max_size=5)
    ),
    max_leaves=30,
)


def _same(a, b) -> bool:
    """Equal values of equal types all the way down (``1 == 1.0`` is not enough)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict):
        return list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, float) and math.isnan(a):
        return math.isnan(b)
    return a == b and (not isinstance(a, float) or math.copysign(1, a) == math.copysign(1, b))


@settings(max_examples=300, deadline=None)
@given(_DOCUMENTS, st.sampled_from([None, 0, 2]))
def test_loads_equals_the_standard_reader(doc, indent):
    raw = json.dumps(doc, indent=indent).encode()
    assert _same(jsontext.loads(raw), json.loads(raw))


@settings(max_examples=200, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False), st.integers(0, 30))
def test_long_decimal_literals_round_as_the_standard_reader(x, extra):
    raw = f"[{x:.{17 + extra}e}, {x:.{1 + extra}f}]".encode()  # decimals, not integers
    assert _same(jsontext.loads(raw), json.loads(raw))


@pytest.mark.parametrize(
    "raw",
    [b"[NaN, Infinity, -Infinity]", b"[1e400]", b'["\\ud800"]', b'{"a": 1, "a": 2}', b"[-0, -0.0]"],
)
def test_documents_orjson_refuses_are_read_by_the_standard_reader(raw):
    assert _same(jsontext.loads(raw), json.loads(raw))


@pytest.mark.parametrize("raw", [b"[1,", b"\xef\xbb\xbf[1]", b"{'a': 1}", b"[\xff]", b""])
def test_bad_documents_raise_the_standard_errors(raw):
    with pytest.raises(ValueError) as ours:
        jsontext.loads(raw)
    with pytest.raises(ValueError) as std:
        json.loads(raw.decode("utf-8"))
    assert type(ours.value) is type(std.value) and str(ours.value) == str(std.value)


def test_integers_past_64_bits_are_never_read_as_ids(tmp_path):
    """orjson reads them as floats; the COCO reader refuses them as ids either way."""
    from torchsar.io import FileFormatError, read_coco_table

    for big in (2**64, -(2**63) - 1):
        path = tmp_path / "gt.json"
        path.write_text(
            json.dumps({"images": [{"id": big, "file_name": "a.png", "height": 4, "width": 4}]})
        )
        with pytest.raises(FileFormatError, match="id"):
            read_coco_table(path)


def test_read_json_reads_a_file(tmp_path):
    path = tmp_path / "a.json"
    path.write_text('{"images": [1, 2.5, "x"]}')
    assert jsontext.read_json(path) == {"images": [1, 2.5, "x"]}
