"""Clutter models: unit mean and moments against scipy.stats references."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import special, stats

from torchsar.errors import InputTypeError, OptionError
from torchsar.simulate import CLUTTER_MODELS, DEFAULT_SHAPE_PARAM, clutter
from torchsar.simulate.clutter import GAMMA_SHAPE_MIN, SHAPE_RANGE

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


def test_deterministic():
    a = clutter((3, 5), model="k", seed=11)
    b = clutter((3, 5), model="k", seed=11)
    assert torch.equal(a, b)
    assert not torch.equal(clutter((3, 5), model="k", seed=12), a)


def test_seed_is_the_only_randomness_option():
    with pytest.raises(TypeError):
        clutter((3, 5), generator=torch.Generator())  # type: ignore[call-arg]


def test_empty_and_float64():
    assert clutter((0, 1, 4, 4)).shape == (0, 1, 4, 4)
    assert clutter((4,), model="g0", dtype=torch.float64).dtype == torch.float64


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"model": "rayleigh"}, "'exponential', 'gamma', 'k', 'g0', 'lognormal', 'weibull'"),
        ({"model": "gamma", "looks": 0.0}, "looks"),
        ({"model": "weibull", "looks": 4.0}, "looks must be 1"),
        ({"model": "g0", "shape_param": 1.0}, "shape_param must be > 1 .*no finite mean"),
        ({"model": "weibull", "shape_param": 0.01}, "shape_param must be >= 0.18 .*float32"),
        ({"model": "lognormal", "shape_param": 9.5}, "shape_param must be > 0 and <= 9"),
        ({"model": "k", "shape_param": 0.1}, "shape_param must be >= 0.16"),
        ({"model": "gamma", "looks": 0.1}, "looks must be >= 0.16"),
        ({"model": "g0", "looks": 0.15}, "looks must be >= 0.16"),
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


# --- parameter ranges: one rule for every model ----------------------------------------------

_P = 1e-6  # the rule's tail probability
_LOG_TINY, _LOG_MAX = math.log(np.finfo(np.float32).tiny), math.log(np.finfo(np.float32).max)


def _factors(model: str, looks: float, p: float | None) -> list:
    """The model's random factors as frozen scipy laws (each unit mean, or (a-1)/G_a)."""
    speckle = stats.gamma(looks, scale=1.0 / looks)
    if model == "k":
        return [speckle, stats.gamma(p, scale=1.0 / p)]
    if model == "g0":
        return [speckle, stats.invgamma(p, scale=p - 1.0)]
    return [_reference(model, looks, p)] if model != "gamma" else [speckle]


def _holds(model: str, looks: float, p: float | None) -> bool:
    """Every factor keeps its 1e-6 and 1 - 1e-6 quantiles in the normal float32 range."""
    for law in _factors(model, looks, p):
        lo, hi = law.ppf(_P), law.isf(_P)
        if not (lo > 0 and math.log(lo) >= _LOG_TINY and math.log(hi) <= _LOG_MAX):
            return False
    return True


# (model, looks, shape_param) at the edges of the documented ranges, and just outside
EDGES = [
    ("gamma", GAMMA_SHAPE_MIN, None, ("gamma", 0.15, None)),
    ("k", GAMMA_SHAPE_MIN, GAMMA_SHAPE_MIN, ("k", 1.0, 0.15)),
    ("g0", GAMMA_SHAPE_MIN, 1.05, ("g0", 0.15, 3.0)),
    ("lognormal", 1.0, SHAPE_RANGE["lognormal"].high, ("lognormal", 1.0, 9.4)),
    ("weibull", 1.0, SHAPE_RANGE["weibull"].low, ("weibull", 1.0, 0.17)),
]


@pytest.mark.parametrize(("model", "looks", "p", "outside"), EDGES)
def test_documented_ranges_follow_the_float32_rule(model, looks, p, outside):
    assert _holds(model, looks, p)
    assert not _holds(*outside)
    with pytest.raises(OptionError, match="float32 cannot hold"):
        clutter((4,), model=outside[0], looks=outside[1], shape_param=outside[2])


def _log_moments(model: str, looks: float, p: float | None) -> tuple[float, float]:
    """Analytic mean and variance of ln I: sums over the independent factors."""
    mean, var = special.digamma(looks) - math.log(looks), special.polygamma(1, looks)
    if model == "weibull":  # ln I = -lgamma(1 + 1/c) + ln(E) / c, E[ln E] = -euler_gamma
        return -math.lgamma(1 + 1 / p) - np.euler_gamma / p, math.pi**2 / (6 * p * p)
    if model == "lognormal":
        return -0.5 * p * p, p * p
    if model == "k":
        return mean + special.digamma(p) - math.log(p), var + special.polygamma(1, p)
    if model == "g0":
        return mean + math.log(p - 1) - special.digamma(p), var + special.polygamma(1, p)
    return mean, var


@pytest.mark.parametrize(("model", "looks", "p", "outside"), EDGES)
def test_fields_at_the_range_edges_are_finite_and_correct(model, looks, p, outside):
    """float32 fields at the most extreme accepted parameters: finite, positive, and the
    log-moments (finite for every law, unlike the plain moments of heavy tails) match."""
    n = 200_000
    x = clutter((n,), model=model, looks=looks, shape_param=p, seed=7).double()
    assert bool(torch.isfinite(x).all()) and bool((x > 0).all())
    logs = x.log()
    mean, var = _log_moments(model, looks, p)
    # s.e. of the mean of ln I is sqrt(var / n); of the variance, ~ var * sqrt(kurtosis / n)
    assert abs(float(logs.mean()) - mean) < 5 * math.sqrt(var / n)
    assert float(logs.var()) == pytest.approx(var, rel=0.05)


@settings(max_examples=40, deadline=None)
@given(
    model=st.sampled_from(["gamma", "k", "g0", "lognormal", "weibull"]),
    u=st.floats(0.0, 1.0),
    v=st.floats(0.0, 1.0),
    seed=st.integers(0, 2**32),
)
def test_every_accepted_parameter_gives_a_finite_field(model, u, v, seed):
    """Any looks / shape_param inside the documented ranges (log-uniform up to 1e4):
    a finite, non-negative float32 field with positive values."""
    looks = GAMMA_SHAPE_MIN * 10 ** (4.8 * u) if model in ("gamma", "k", "g0") else 1.0
    p = None
    if model != "gamma":
        r = SHAPE_RANGE[model]
        low = r.low if r.closed else (r.low + 1e-3 if model == "g0" else 1e-3)
        p = low * (min(r.high, 1e4) / low) ** v
    x = clutter((2_000,), model=model, looks=looks, shape_param=p, seed=seed)
    assert bool(torch.isfinite(x).all()) and bool((x >= 0).all()) and bool((x > 0).any())
