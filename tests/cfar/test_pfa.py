"""The false-alarm promise, measured: homogeneous clutter of each detector's model at design
Pfa 1e-3 (guard 2, train 4) over ~0.5 M pixels, every pixel counted (border rule included).
K (nu = 2) and G0 (a = 3) at one look are the hard cases: a 144-cell ring barely tells
their shape from the speckle-only limit (:mod:`torchsar.cfar.log_t`)."""

from __future__ import annotations

import pytest
import torch

import torchsar as ts
from tests.reference.cfar import sample_clutter

PFA = 1e-3


@pytest.fixture(scope="module")
def exponential() -> torch.Tensor:
    gen = torch.Generator().manual_seed(2024)
    return torch.empty(1, 1, 512, 512).exponential_(generator=gen)


@pytest.mark.parametrize("name", ["ca", "go", "so", "os", "vi", "ac"])
def test_measured_pfa_exponential(exponential, name):
    d = getattr(ts.cfar, name)(exponential, guard=2, train=4, pfa=PFA)
    measured = d.mask.double().mean().item()
    assert 0.6e-3 <= measured <= 1.6e-3, f"{name}: measured Pfa {measured:.2e}"


@pytest.mark.parametrize(
    ("name", "model", "kw"),
    [
        ("lognormal", "lognormal", {}),
        ("weibull", "weibull", {}),
        ("gamma", "gamma", {"looks": 4.0}),
        ("k", "k", {}),
        ("g0", "g0", {}),  # the simulator's default single look, roughness a = 3
    ],
)
def test_measured_pfa_own_model(name, model, kw):
    x = torch.from_numpy(sample_clutter(model, (2, 1, 512, 512), 11, looks=kw.get("looks", 1.0)))
    d = getattr(ts.cfar, name)(x.float(), guard=2, train=4, pfa=PFA, **kw)
    measured = d.mask.double().mean().item()
    assert 0.5e-3 <= measured <= 2e-3, f"{name} on {model}: measured Pfa {measured:.2e}"
