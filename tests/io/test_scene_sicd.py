"""SicdScene: windows through a stand-in for sarpy's reader (sarpy is an optional extra)."""

from __future__ import annotations

import importlib.util
import pickle

import numpy as np
import pytest

import torchsar.io.sicd as sicd
from torchsar.io import SicdScene, WindowError, open_scene

rng = np.random.default_rng(4)
DATA = (rng.normal(size=(40, 33)) + 1j * rng.normal(size=(40, 33))).astype(np.complex64)


class _Grid:
    class Row:
        SS = 0.4

    class Col:
        SS = 0.6


class _FakeReader:
    """The part of sarpy's complex reader that SicdScene uses."""

    closed = False

    def get_data_size_as_tuple(self):
        return (DATA.shape,)

    def __getitem__(self, key):
        return DATA[key]

    def get_sicds_as_tuple(self):
        return (type("Sicd", (), {"Grid": _Grid})(),)

    def close(self):
        self.closed = True


@pytest.fixture
def product(tmp_path, monkeypatch):
    path = tmp_path / "p.nitf"
    path.write_bytes(b"NITF02.10 stand-in")
    monkeypatch.setattr(sicd, "_open", lambda path: _FakeReader())
    return path


def test_windows_spacing_and_intensity(product):
    with open_scene(product) as scene:
        assert isinstance(scene, SicdScene)
        assert scene.shape == (40, 33) and scene.dtype == np.complex64
        assert scene.pixel_spacing == (0.4, 0.6) and scene.sample_type == "complex"
        np.testing.assert_array_equal(scene[5:30, 7:33], DATA[5:30, 7:33])
        assert scene[3:3, 0:5].shape == (0, 5)
        with pytest.raises(WindowError, match="cols"):
            scene[0:5, 30:34]
        reader = scene._reader
    assert reader.closed
    with open_scene(product, as_intensity=True) as scene:
        assert scene.dtype == np.float32
        np.testing.assert_allclose(scene[0:10, 0:10], np.abs(DATA[:10, :10]) ** 2, rtol=1e-5)
        clone = pickle.loads(pickle.dumps(scene))
        np.testing.assert_array_equal(clone[1:4, 2:9], scene[1:4, 2:9])


@pytest.mark.skipif(importlib.util.find_spec("sarpy") is not None, reason="sarpy is installed")
def test_without_sarpy_a_nitf_says_what_to_install(tmp_path):
    path = tmp_path / "p.nitf"
    path.write_bytes(b"NITF02.10 not really")
    with pytest.raises(ImportError, match="sarpy"):
        open_scene(path)
