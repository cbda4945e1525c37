"""Clutter models: unit mean and moments against scipy.stats references."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy import special, stats

from torchsar._checks import InputTypeError, OptionError
from torchsar.simulate import CLUTTER_MODELS, DEFAULT_SHAPE_PARAM, clutter

N = 400_000  # samples per moment check


def _reference(model: str, looks: float, p: float | None):
    """A frozen scipy.stats law of the unit-mean intensity, built independently."""
    if model == "exponential":
        return stats.expon()
    if model == "gamma":
        return stats.gamma(looks, scale=1.0 / looks)
    if model == "g0":  # I = (a-1)/a * F(2L, 2a)
        return stats.f(2 * looks, 2 * p, scale=(p - 1.0) / p)
    if model == "lognormal":
        return stats.lognorm(p, scale=math.exp(-0.5 * p * p))
    if model == "weibull":
        return stats.weibull_min(p, scale=1.0 / special.gamma(1.0 + 1.0 / p))
    raise AssertionError(model)


def _k_moment(n: int, looks: float, nu: float) -> float:
    """E[I^n] of the K law as the product of two independent gamma moments."""
    g = stats.gamma(looks, scale=1.0 / looks).moment(n)
    t = stats.gamma(nu, scale=1.0 / nu).moment(n)
    return g * t


def _moment(model: str, n: int, looks: float, p: float | None) -> float:
    """Analytic E[I^n] from the scipy reference laws."""
    return _k_moment(n, looks, p) if model == "k" else _reference(model, looks, p).moment(n)


CASES = [
    ("exponential", 1.0, None),
    ("gamma", 1.0, None),
    ("gamma", 4.0, None),
    ("k", 1.0, 2.0),
    ("k", 3.0, 5.0),
    ("g0", 1.0, 5.0),
    ("g0", 4.0, 8.0),
    ("lognormal", 1.0, 0.5),
    ("weibull", 1.0, 1.5),
]


@pytest.mark.parametrize(("model", "looks", "p"), CASES)
def test_moments_match_reference(model, looks, p):
    x = clutter((N,), model=model, looks=looks, shape_param=p, seed=3, dtype=torch.float64)
    x = x.numpy()
    assert (x >= 0).all()
    for n in (1, 2):
        ref = _k_moment(n, looks, p) if model == "k" else _reference(model, looks, p).moment(n)
        ref2n = (
            _k_moment(2 * n, looks, p)
            if model == "k"
            else _reference(model, looks, p).moment(2 * n)
        )
        # standard error of the sample moment mean(x^n): sqrt(Var(x^n) / N); allow 5 sigma
        se = math.sqrt((ref2n - ref**2) / N)
        assert abs(np.mean(x**n) - ref) < 5 * se, (model, n)


@pytest.mark.parametrize(("model", "looks", "p"), [c for c in CASES if c[0] != "k"])
def test_distribution_ks(model, looks, p):
    x = clutter((20_000,), model=model, looks=looks, shape_param=p, seed=5, dtype=torch.float64)
    assert stats.kstest(x.numpy(), _reference(model, looks, p).cdf).pvalue > 1e-3


@pytest.mark.parametrize("looks", [1.0, 2.0, 8.0])
def test_gamma_enl(looks):
    x = clutter((200_000,), model="gamma", looks=looks, seed=1, dtype=torch.float64)
    enl = float(x.mean() ** 2 / x.var())
    # ENL estimate has relative s.e. ~ sqrt((2 + 6/L) / N) < 1%: allow 4 %
    assert enl == pytest.approx(looks, rel=0.04)


@pytest.mark.parametrize("model", CLUTTER_MODELS)
def test_unit_mean_defaults(model):
    x = clutter((2, 1, 128, 128), model=model, seed=0)
    assert x.shape == (2, 1, 128, 128) and x.dtype == torch.float32
    assert float(x.mean()) == pytest.approx(1.0, abs=0.06)  # >= 4.7 s.e. for default params


def test_k_texture_is_spikier_than_speckle():
    k = clutter((200_000,), model="k", looks=1.0, shape_param=1.0, seed=0)
    e = clutter((200_000,), model="exponential", seed=0)
    assert float((k**2).mean()) > 1.5 * float((e**2).mean())


def test_defaults_listed():
    assert set(DEFAULT_SHAPE_PARAM) == set(CLUTTER_MODELS)


def test_deterministic_and_generator():
    a = clutter((3, 5), model="k", seed=11)
    b = clutter((3, 5), model="k", seed=11)
    assert torch.equal(a, b)
    g = torch.Generator().manual_seed(11)
    assert torch.equal(clutter((3, 5), model="k", generator=g), a)
    assert not torch.equal(clutter((3, 5), model="k", seed=12), a)


def test_empty_and_float64():
    assert clutter((0, 1, 4, 4)).shape == (0, 1, 4, 4)
    assert clutter((4,), model="g0", dtype=torch.float64).dtype == torch.float64


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"model": "rayleigh"}, "'exponential', 'gamma', 'k', 'g0', 'lognormal', 'weibull'"),
        ({"model": "gamma", "looks": 0.0}, "looks"),
        ({"model": "weibull", "looks": 4.0}, "looks must be 1"),
        ({"model": "g0", "shape_param": 1.0}, "shape_param must be > 1"),
        ({"model": "k", "shape_param": -1.0}, "shape_param"),
        ({"model": "gamma", "shape_param": 2.0}, "shape_param must be None"),
        ({"seed": -1}, "seed"),
    ],
)
def test_errors(kwargs, match):
    with pytest.raises(OptionError, match=match):
        clutter((4,), **kwargs)


def test_bad_shape_and_dtype():
    with pytest.raises(OptionError, match="shape"):
        clutter((4, -1))
    with pytest.raises(InputTypeError, match="dtype"):
        clutter((4,), dtype=torch.int32)
