"""sicd: chips through a stand-in for sarpy's reader (sarpy is an optional extra)."""

from __future__ import annotations

import importlib.util
import warnings

import numpy as np
import pytest

import torchsar.io.sicd as sicd
from tests.eval.datasets_helpers import check_contract
from torchsar_eval.datasets import make_dataset
from torchsar_eval.datasets.sicd import chip_regions
from torchsar_eval.errors import EvalError

rng = np.random.default_rng(2)
DATA = (rng.normal(size=(10, 13)) + 1j * rng.normal(size=(10, 13))).astype(np.complex64)


class _Grid:
    class Row:
        SS = 0.4

    class Col:
        SS = 0.6


class _FakeReader:
    """The part of sarpy's complex reader that read_sicd uses."""

    def get_data_size_as_tuple(self):
        return (DATA.shape,)

    def __getitem__(self, key):
        return DATA[key]

    def get_sicds_as_tuple(self):
        return (type("Sicd", (), {"Grid": _Grid})(),)


def test_chips_regions_spacing_and_intensity(tmp_path, monkeypatch):
    product = tmp_path / "p.nitf"
    product.write_bytes(b"stand-in")
    monkeypatch.setattr(sicd, "_open", lambda path: _FakeReader())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ds = make_dataset(f"sicd:{product}?chip=4")
    assert chip_regions(10, 13, 4) == [(r, c, r + 4, c + 4) for r in (0, 4) for c in (0, 4, 8)]
    assert len(ds) == 6
    item = ds[4]
    check_contract(item)
    np.testing.assert_allclose(item["image"][0].numpy(), np.abs(DATA[4:8, 4:8]) ** 2, rtol=1e-5)
    assert item["meta"]["pixel_spacing"] == (0.4, 0.6) and item["meta"]["region"] == (4, 4, 8, 8)
    assert not item["mask"].any() and ds.options["sample_type"] == "complex"


@pytest.mark.skipif(importlib.util.find_spec("sarpy") is not None, reason="sarpy is installed")
def test_without_sarpy_the_error_says_what_to_install(tmp_path):
    product = tmp_path / "p.nitf"
    product.write_bytes(b"x")
    with pytest.raises(EvalError, match=r"pip install 'sarpy>=1.3'"):
        make_dataset(f"sicd:{product}")
