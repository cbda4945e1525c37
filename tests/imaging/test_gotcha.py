"""Real-data tests on the GOTCHA sample (skipped when ../shared/data is absent)."""

from __future__ import annotations

import math

import pytest
import torch

import torchsar.imaging as ti
from torchsar.imaging.backprojection import BackprojectionOperator
from torchsar.imaging.pulse_autofocus import pulse_autofocus
from torchsar.io import gotcha_files, read_gotcha


@pytest.fixture(scope="module")
def gotcha(request):
    from pathlib import Path

    folder = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "gotcha"
    if not folder.is_dir():
        pytest.skip(f"GOTCHA data folder {folder} not present")
    return folder


@pytest.fixture(scope="module")
def scene(gotcha):
    data = read_gotcha(gotcha).autofocused()
    axis = torch.linspace(-25, 25, 41, dtype=torch.float64)
    op = BackprojectionOperator(data.freq, data.antenna, data.r0, axis, axis)
    return data, op


class TestReader:
    def test_shapes(self, gotcha):
        files = gotcha_files(gotcha)
        assert len(files) == 4
        one = read_gotcha(files[0])
        assert one.phase_history.shape == (117, 424)
        assert one.phase_history.dtype == torch.complex64
        full = read_gotcha(gotcha)
        assert full.phase_history.shape == (469, 424)
        assert full.antenna.shape == (469, 3) and full.r0.shape == (469,)
        assert (full.freq.diff() > 0).all()
        torch.testing.assert_close(full.antenna.norm(dim=1), full.r0, rtol=1e-4, atol=0)

    def test_missing_folder(self, tmp_path):
        with pytest.raises(FileNotFoundError, match="no GOTCHA files"):
            read_gotcha(tmp_path)

    def test_afrl_solution_focuses(self, gotcha, scene):
        _, op = scene
        raw = read_gotcha(gotcha)
        e_raw = ti.entropy(op.adjoint(raw.phase_history[None]).abs().square())
        e_af = ti.entropy(op.adjoint(raw.autofocused().phase_history[None]).abs().square())
        assert e_af < e_raw


class TestInjectedErrors:
    def test_sparse_corrects_quadratic_error(self, scene):
        data, op = scene
        g0 = data.phase_history[None]
        phi = ti.quadratic_phase_error(1, 469, amplitude=4 * math.pi, seed=0).double()
        b = (
            op.pulse_images(g0)
            * torch.polar(torch.ones_like(phi), phi).to(torch.complex64)[..., None, None]
        )
        blurred = ti.entropy(b.sum(1, keepdim=True).abs().square())
        out = pulse_autofocus(b)
        img, est = out.image, out.phase
        assert ti.phase_rmse(est.double(), phi).item() < 0.5
        assert ti.entropy(img.abs().square()) < blurred
