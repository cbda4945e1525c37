"""The typed option parsers: round trips, and every bad value named in one EvalError."""

from __future__ import annotations

import math
import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from torchsar_eval.errors import EvalError
from torchsar_eval.options import at_least, floats, ints, names


@given(st.lists(st.integers(-50, 50), min_size=1, max_size=6))
def test_ints_round_trip_and_range(values):
    text = ", ".join(map(str, values))
    if min(values) >= 0:
        assert ints(text, "--guards", minimum=0) == values
    else:
        with pytest.raises(EvalError, match=r"^--guards (values )?must be >= 0, got"):
            ints(text, "--guards", minimum=0)


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=1, max_size=6))
def test_floats_accept_exactly_the_finite_values_in_range(values):
    text = ",".join(map(repr, values))
    if all(math.isfinite(v) and 0 < v < 1 for v in values):
        assert floats(text, "--pfa", above=0, below=1) == values
    else:
        with pytest.raises(EvalError, match=r"^--pfa (values )?must be > 0 and < 1, got"):
            floats(text, "--pfa", above=0, below=1)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: ints("", "--n"), "--n is empty"),
        (lambda: ints(" , ", "--n"), "--n is empty"),
        (lambda: ints("3,x", "--windows"), "--windows must be comma-separated integers"),
        (lambda: floats("abc", "--speeds"), "--speeds must be comma-separated numbers"),
        (lambda: floats("nan", "--speeds"), "--speeds must be finite, got nan"),
        (lambda: floats("1,2", "--x", minimum=0, maximum=1), "--x values must be >= 0 and <= 1"),
        (
            lambda: names("ca,zz", "--detectors", ["ca"], what="detector"),
            "--detectors: unknown detector 'zz'",
        ),
        (lambda: names("ca,ca", "--detectors", ["ca"]), "--detectors lists ca more than once"),
        (lambda: at_least(0, "--batch-size", 1), "--batch-size must be >= 1, got 0"),
    ],
)
def test_errors_name_the_option(call, message):
    with pytest.raises(EvalError, match="^" + re.escape(message)):
        call()


def test_at_least_passes_values_and_none_through():
    assert at_least(None, "--n", 1) is None and at_least(3, "--n", 1) == 3
