"""Speckle filters under autograd: same values, correct gradients, finite at degenerate
windows (constant and zero areas, lone bright pixels)."""

from __future__ import annotations

import pytest
import torch

from tests.speckle._cases import NAMES, call, speckled
from torchsar import _jit


def _tiny(seed: int) -> torch.Tensor:
    """A 7x8 float64 image whose 3x3 windows fall in every Ci class (see _cases)."""
    return speckled((1, 1, 7, 8), looks=1.0, seed=seed) + 0.05


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("amplitude", [False, True])
def test_gradcheck(name, amplitude):
    x = _tiny(3).requires_grad_()
    assert torch.autograd.gradcheck(
        lambda t: call(name, t, window=3, looks=2.0, damping=1.5, amplitude=amplitude), (x,)
    )


@pytest.mark.parametrize("name", NAMES)
def test_values_unchanged_by_autograd(name, monkeypatch):
    """The tensor code gives the same values with and without autograd (without it, CPU
    tensors may take a compiled kernel instead: compared in tests/test_box_kernels.py)."""
    monkeypatch.setattr(_jit, "ENABLED", False)
    x = speckled((2, 1, 12, 13), looks=1.0, seed=4)
    want = call(name, x, window=5, looks=2.0)
    got = call(name, x.clone().requires_grad_(), window=5, looks=2.0)
    assert got.requires_grad
    torch.testing.assert_close(got.detach(), want, rtol=0, atol=0)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("amplitude", [False, True])
def test_finite_gradient_on_degenerate_windows(name, amplitude):
    x = torch.zeros(3, 1, 9, 9, dtype=torch.float64)
    x[1] = 2.0
    x[2, 0, 4, 4] = 100.0
    x.requires_grad_()
    call(name, x, window=3, looks=1.0, amplitude=amplitude).sum().backward()
    assert bool(torch.isfinite(x.grad).all())
    # around a constant image every filter is a normalised local mean (Ci has zero
    # derivative there), so the gradient of the sum is 1 where no window is truncated
    inner = x.grad[1, 0, 2:-2, 2:-2]
    torch.testing.assert_close(inner, torch.ones_like(inner), rtol=1e-9, atol=1e-9)
