"""The false-alarm promise, measured: homogeneous clutter of each detector's model at design
Pfa 1e-3 (guard 2, train 4) over ~0.5 M pixels, every pixel counted (border rule included)."""

from __future__ import annotations

import pytest
import torch

import torchsar as ts

PFA = 1e-3


@pytest.fixture(scope="module")
def exponential() -> torch.Tensor:
    gen = torch.Generator().manual_seed(2024)
    return torch.empty(2, 1, 512, 512).exponential_(generator=gen)


@pytest.mark.parametrize("name", ["ca", "go", "so", "os"])
def test_measured_pfa_exponential(exponential, name):
    d = getattr(ts.cfar, name)(exponential, guard=2, train=4, pfa=PFA)
    measured = d.mask.double().mean().item()
    assert 0.6e-3 <= measured <= 1.6e-3, f"{name}: measured Pfa {measured:.2e}"
