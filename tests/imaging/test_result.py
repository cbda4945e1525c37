"""Every autofocus method returns the one result family with the shared fields."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from torchsar.imaging import (
    AutofocusResult,
    MinEntropyResult,
    SparseAutofocusResult,
    apply_phase_error,
    fft2c,
    ifft2c,
    min_entropy_autofocus,
    pga,
    pulse_autofocus,
    pulse_min_entropy,
    sparse_autofocus,
)
from torchsar.imaging.result import fill_result


def _data(b: int = 2, n: int = 16) -> torch.Tensor:
    f = torch.zeros(b, n, n, dtype=torch.complex64)
    f[:, 3, 5], f[:, 9, 12] = 1.0, 0.7
    phi = 1.5 * torch.linspace(-1, 1, n)[None].expand(b, n) ** 2
    return apply_phase_error(fft2c(f), phi)


def _pulses(g: torch.Tensor) -> torch.Tensor:
    """Per-pulse images of ``g`` under the unitary FFT: ``b_m = ifft2c(g masked to pulse m)``."""
    m = g.shape[1]
    eye = torch.eye(m, dtype=g.dtype)[None, :, :, None]  # (1, M, M, 1)
    return ifft2c((g[:, None] * eye).flatten(0, 1)).unflatten(0, (g.shape[0], m))


METHODS = {
    "sparse": (lambda g: sparse_autofocus(g, max_iter=5), SparseAutofocusResult),
    "pga": (lambda g: pga(ifft2c(g).unsqueeze(1), max_iter=3), AutofocusResult),
    "min-entropy": (lambda g: min_entropy_autofocus(g, max_iter=5), MinEntropyResult),
    "pulse": (lambda g: pulse_autofocus(_pulses(g), max_iter=5), AutofocusResult),
    "pulse-min-entropy": (lambda g: pulse_min_entropy(_pulses(g), max_iter=5), MinEntropyResult),
}


class TestResultFamily:
    @pytest.mark.parametrize("name", list(METHODS))
    def test_shared_fields(self, name):
        method, kind = METHODS[name]
        out = method(_data())
        assert type(out) is kind and isinstance(out, AutofocusResult)
        assert out.image.shape == (2, 1, 16, 16) and out.image.is_complex()
        assert out.phase.shape == (2, 16) and not out.phase.is_complex()
        assert out.iterations.shape == (2,) and out.iterations.dtype == torch.int64
        assert (out.iterations >= 0).all() and (out.iterations <= 5).all()
        with pytest.raises(dataclasses.FrozenInstanceError):
            out.image = out.image  # type: ignore[misc]

    @pytest.mark.parametrize("name", list(METHODS))
    def test_phase_corrects_the_data(self, name):
        """The estimate follows one convention: ``apply_phase_error(g, -phase)`` refocuses."""
        g = _data()
        out = METHODS[name][0](g)
        before = ifft2c(g).abs().amax(dim=(-2, -1))
        after = ifft2c(apply_phase_error(g, -out.phase.to(torch.float32))).abs()
        assert (after.amax(dim=(-2, -1)) > before).all()

    def test_min_entropy_reports_its_objective(self):
        out = min_entropy_autofocus(_data(), max_iter=20)
        assert out.iterations.unique().numel() == 1  # one L-BFGS run for the batch
        assert int(out.iterations[0]) >= 1
        i = out.image.abs().square().flatten(1)
        q = i / i.sum(1, keepdim=True)
        torch.testing.assert_close(out.entropy, -(q * q.log()).nan_to_num().sum(1))

    def test_fill_result_keeps_the_subclass(self):
        part = MinEntropyResult(
            torch.ones(1, 1, 2, 2, dtype=torch.complex64),
            torch.ones(1, 3),
            torch.tensor([4]),
            torch.tensor([0.5]),
        )
        full = fill_result(torch.tensor([True, False]), part)
        assert type(full) is MinEntropyResult
        assert full.iterations.tolist() == [4, 0] and full.entropy.tolist() == [0.5, 0.0]
        assert (full.image[1] == 0).all() and full.phase.shape == (2, 3)
