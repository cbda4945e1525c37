"""Fixtures of the region tests: run a test under both paths of the detector."""

from __future__ import annotations

import importlib.util

import pytest

from torchsar import _jit

HAVE_NUMBA = importlib.util.find_spec("numba") is not None


@pytest.fixture(scope="class", params=["python", "compiled"])
def path(request):
    """The Python path (heap, flood fills, numpy rings) or the compiled kernel
    (:mod:`torchsar.region._kernels`, needs numba) for the whole detector."""
    if request.param == "compiled" and not HAVE_NUMBA:
        pytest.skip("numba is not installed")
    old = _jit.ENABLED
    _jit.ENABLED = request.param == "compiled"
    yield request.param
    _jit.ENABLED = old
