"""MSTAR Phoenix files: synthetic files with known content, lying headers, the real sample."""

from __future__ import annotations

import numpy as np
import pytest

from tests.io.writers import write_phoenix
from torchsar.io import FileFormatError, is_phoenix, read_phoenix

rng = np.random.default_rng(1)


def _chip(h=6, w=5):
    return rng.random((h, w)).astype(np.float32), (2 * np.pi * rng.random((h, w))).astype(
        np.float32
    )


def test_synthetic_file_reads_back(tmp_path):
    mag, ph = _chip()
    path = write_phoenix(tmp_path / "HB00001.015", mag, ph, spacing=(0.2, 0.25))
    assert is_phoenix(path)
    chip = read_phoenix(path)
    np.testing.assert_array_equal(chip.magnitude, mag)
    np.testing.assert_array_equal(chip.phase, ph)
    assert chip.pixel_spacing == (0.2, 0.25)
    assert chip.header["TargetType"] == "T72"
    np.testing.assert_allclose(chip.complex, mag * np.exp(1j * ph), rtol=1e-6)


def test_missing_spacing_is_none(tmp_path):
    mag, ph = _chip()
    assert read_phoenix(write_phoenix(tmp_path / "x", mag, ph, spacing=None)).pixel_spacing is None


@pytest.mark.parametrize("rows", [5, 7, 600])
def test_header_that_lies_about_the_size(tmp_path, rows):
    mag, ph = _chip()
    path = write_phoenix(tmp_path / "lie.015", mag, ph, rows=rows)
    with pytest.raises(FileFormatError, match=rf"lie.015: Phoenix header says {rows}x5"):
        read_phoenix(path)


def test_truncated_data_and_foreign_files(tmp_path):
    mag, ph = _chip()
    path = write_phoenix(tmp_path / "cut.015", mag, ph)
    path.write_bytes(path.read_bytes()[:-4])
    with pytest.raises(FileFormatError, match="cut.015: Phoenix header says 6x5"):
        read_phoenix(path)
    other = tmp_path / "notes.015"
    other.write_text("hello")
    assert not is_phoenix(other)
    with pytest.raises(FileFormatError, match="notes.015: is not an MSTAR Phoenix file"):
        read_phoenix(other)


def test_pixel_limit_before_reading(tmp_path):
    mag, ph = _chip()
    with pytest.raises(FileFormatError, match="max_pixels=29"):
        read_phoenix(write_phoenix(tmp_path / "x", mag, ph), max_pixels=29)


def test_real_mstar_file(data_dir):
    chip = read_phoenix(data_dir / "mstar_raw" / "HB14931.015")
    assert chip.magnitude.shape == (54, 54)
    assert chip.pixel_spacing == (0.202148, 0.203125)
    assert 1.9 < chip.magnitude.max() < 1.92 and chip.magnitude.min() >= 0
    assert chip.phase.min() >= 0 and chip.phase.max() < 2 * np.pi + 1e-5
    assert chip.header["TargetType"] == "slicey"
