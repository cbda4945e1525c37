"""Unit-mean intensity clutter models: exponential, gamma, K, G0, log-normal, Weibull.

Every model returns **intensity** ``I >= 0`` normalised to ``E[I] = 1``; multiply by the local
mean reflectivity to get a clutter field of any mean. ``L`` is ``looks``; ``shape_param`` is
the model's second parameter (default in brackets). ``G_a`` below is a standard gamma variate
of shape ``a`` (density ``x^(a-1) e^-x / Gamma(a)``), ``Y_L = G_L / L`` unit-mean L-look speckle.

==============  =================================  ==========================================
model           sample                             moments ``E[I^n]``
==============  =================================  ==========================================
``exponential`` ``G_1`` (single-look speckle)      ``n!``
``gamma``       ``Y_L``                            ``Gamma(L+n) / (Gamma(L) L^n)``
``k``           ``X * Y_L``, ``X = G_nu / nu``     ``gamma-moment(L, n) * Gamma(nu+n) /
                (nu = shape_param [2.0] > 0)        (Gamma(nu) nu^n)``
``g0``          ``X * Y_L``, ``X = (a-1) / G_a``   ``gamma-moment(L, n) * (a-1)^n *
                (a = shape_param [3.0] > 1)         Gamma(a-n) / Gamma(a)``  (n < a)
``lognormal``   ``exp(s Z - s^2/2)``, Z ~ N(0, 1)  ``exp(n (n-1) s^2 / 2)``
                (s = shape_param [1.0] > 0)
``weibull``     ``lam * G_1^(1/c)``,               ``Gamma(1 + n/c) / Gamma(1 + 1/c)^n``
                ``lam = 1 / Gamma(1 + 1/c)``
                (c = shape_param [0.8] > 0)
==============  =================================  ==========================================

Exact laws for thresholds (all unit mean):

- gamma: density ``L^L I^(L-1) e^(-L I) / Gamma(L)``; ``P(I > t) = Q(L, L t)`` (regularised
  upper incomplete gamma), quantile ``gammaincinv(L, 1 - pfa) / L``.
- k: texture ``X ~ Gamma(shape nu, scale 1/nu)``; density
  ``2 (L nu)^((L+nu)/2) I^((L+nu)/2 - 1) K_(nu-L)(2 sqrt(L nu I)) / (Gamma(L) Gamma(nu))``.
- g0: the intensity G0 law of Frery et al. (1997) with roughness ``alpha_G0 = -a`` (``a > 1``)
  and scale ``gamma = a - 1``; ``X`` is inverse gamma (shape ``a``, scale ``a - 1``); density
  ``L^L Gamma(L+a) gamma^a I^(L-1) / (Gamma(L) Gamma(a) (gamma + L I)^(L+a))``; equivalently
  ``I = (a - 1)/a * F`` with ``F ~ F(2L, 2a)`` (Fisher–Snedecor), so the quantile is
  ``(a - 1)/a * scipy.stats.f.ppf(1 - pfa, 2L, 2a)``. Small ``a`` = heterogeneous (urban),
  large ``a`` tends to gamma. Variance is finite only for ``a > 2``.
- lognormal: ``ln I ~ N(-s^2/2, s^2)``; quantile ``exp(-s^2/2 + s Phi^-1(1 - pfa))``.
- weibull: ``P(I > t) = exp(-(t / lam)^c)``; quantile ``lam (-ln pfa)^(1/c)``.
  ``c = 1`` is the exponential law, ``c < 1`` spikier.

``looks`` applies to ``gamma``, ``k`` and ``g0``; ``exponential``, ``lognormal`` and
``weibull`` are complete intensity laws and require ``looks == 1``.

Parameter ranges (one rule for every model): a parameter is accepted when every random
factor of the model keeps its ``1e-6`` and ``1 - 1e-6`` quantiles inside the normal float32
range ``[1.2e-38, 3.4e38]``, so a field holds no spurious zeros, infinities or NaN:
``looks`` and K's ``nu`` >= 0.16 (a gamma variate of smaller shape underflows), Weibull
``c`` >= 0.18, log-normal ``s`` <= 9, G0 ``a > 1`` (any). Outside, :class:`OptionError`
names the parameter and its range.

References:
    Oliver, C., Quegan, S. (2004). Understanding Synthetic Aperture Radar Images. SciTech.
    Frery, A. C. et al. (1997). A model for extremely heterogeneous clutter. IEEE TGRS 35(3),
    648–659. DOI: 10.1109/36.581981
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar._checks import check_choice, check_int, check_positive
from torchsar.errors import InputTypeError, OptionError
from torchsar.seeding import check_device, check_seed, make_generator

__all__ = [
    "CLUTTER_MODELS",
    "DEFAULT_SHAPE_PARAM",
    "GAMMA_SHAPE_MIN",
    "LOOKS_RANGE",
    "SHAPE_RANGE",
    "ClutterSpec",
    "ParamRange",
    "clutter",
    "clutter_spec",
]

CLUTTER_MODELS = ("exponential", "gamma", "k", "g0", "lognormal", "weibull")
"""The allowed ``model`` names."""

DEFAULT_SHAPE_PARAM: dict[str, float | None] = {
    "exponential": None,
    "gamma": None,
    "k": 2.0,
    "g0": 3.0,
    "lognormal": 1.0,
    "weibull": 0.8,
}
"""``shape_param`` used when ``None`` is given (``None``: the model has no shape parameter)."""

_SPECKLED = ("gamma", "k", "g0")

GAMMA_SHAPE_MIN = 0.16
"""Smallest shape of a gamma variate (``looks``, K's ``nu``) whose law float32 holds."""

_FLOAT32 = "outside, float32 cannot hold the law: samples would underflow to 0 or overflow"


@dataclass(frozen=True)
class ParamRange:
    """The accepted values ``low <(=) value <= high`` of a parameter, and why."""

    low: float
    closed: bool
    high: float = math.inf
    why: str = _FLOAT32

    def check(self, value: float, name: str, model: str) -> float:
        """Return ``value``, or raise :class:`OptionError` naming ``name`` and the range."""
        if (value >= self.low if self.closed else value > self.low) and value <= self.high:
            return value
        bound = f"{'>=' if self.closed else '>'} {self.low:g}"
        bound += f" and <= {self.high:g}" if self.high < math.inf else ""
        raise OptionError(f"{name} must be {bound} for model {model!r} ({self.why}), got {value!r}")


LOOKS_RANGE = ParamRange(GAMMA_SHAPE_MIN, True)
"""Accepted ``looks`` of the speckled models (gamma, k, g0)."""

SHAPE_RANGE: dict[str, ParamRange] = {
    "k": ParamRange(GAMMA_SHAPE_MIN, True),
    "g0": ParamRange(1.0, False, why="for a <= 1 the law has no finite mean"),
    "lognormal": ParamRange(0.0, False, 9.0),
    "weibull": ParamRange(0.18, True),
}
"""The accepted ``shape_param`` of each model (see the module docstring)."""


@dataclass(frozen=True)
class ClutterSpec:
    """A validated clutter model: ``model``, ``looks`` and the resolved ``shape_param``."""

    model: str
    looks: float
    shape_param: float | None

    def as_dict(self) -> dict[str, object]:
        """The spec as a plain dict (for metadata)."""
        return {"model": self.model, "looks": self.looks, "shape_param": self.shape_param}


def clutter_spec(model: object, *, looks: object = 1.0, shape_param: object = None) -> ClutterSpec:
    """Validate a clutter model and resolve its default ``shape_param``.

    Raises:
        OptionError: unknown model (the allowed ones are listed), ``looks`` not > 0 or not 1
            for a model without looks, ``shape_param`` out of range or given to a model that
            has none.
    """
    name = check_choice(model, "model", CLUTTER_MODELS)
    L = check_positive(looks, "looks")
    if name in _SPECKLED:
        LOOKS_RANGE.check(L, "looks", name)
    if name not in _SPECKLED and L != 1.0:
        raise OptionError(
            f"looks must be 1 for model {name!r} (a complete intensity law), got {looks!r}; "
            f"use one of {', '.join(map(repr, _SPECKLED))} for multi-look clutter"
        )
    if name in ("exponential", "gamma"):
        if shape_param is not None:
            raise OptionError(f"shape_param must be None for model {name!r}, got {shape_param!r}")
        return ClutterSpec(name, L, None)
    value = DEFAULT_SHAPE_PARAM[name] if shape_param is None else shape_param
    p = check_positive(value, "shape_param")
    SHAPE_RANGE[name].check(p, "shape_param", name)
    return ClutterSpec(name, L, p)


def _gamma(shape: Sequence[int], a: float, gen: torch.Generator, dtype: torch.dtype) -> Tensor:
    """Standard gamma variates ``G_a`` (unit scale)."""
    conc = torch.full(tuple(shape), a, dtype=dtype, device=gen.device)
    return torch._standard_gamma(conc, generator=gen)


def sample_clutter(
    spec: ClutterSpec, shape: Sequence[int], generator: torch.Generator, dtype: torch.dtype
) -> Tensor:
    """Draw a unit-mean clutter field of ``shape`` for a validated ``spec`` (no checks)."""
    m, L, p = spec.model, spec.looks, spec.shape_param
    dev = generator.device
    if m == "exponential" or (m == "gamma" and L == 1.0):
        return torch.empty(tuple(shape), dtype=dtype, device=dev).exponential_(generator=generator)
    if m == "lognormal":
        z = torch.randn(tuple(shape), dtype=dtype, device=dev, generator=generator)
        return torch.exp(p * z - 0.5 * p * p)
    if m == "weibull":
        e = torch.empty(tuple(shape), dtype=dtype, device=dev).exponential_(generator=generator)
        return e.pow(1.0 / p) * math.exp(-math.lgamma(1.0 + 1.0 / p))
    speckle = _gamma(shape, L, generator, dtype) / L
    if m == "gamma":
        return speckle
    if m == "k":
        return speckle * (_gamma(shape, p, generator, dtype) / p)
    return speckle * ((p - 1.0) / _gamma(shape, p, generator, dtype))  # g0


def _check_shape(shape: object) -> tuple[int, ...]:
    """Validate a shape: a sequence of non-negative ints."""
    if isinstance(shape, int) and not isinstance(shape, bool):
        shape = (shape,)
    if not isinstance(shape, Sequence | torch.Size):
        raise OptionError(f"shape must be a tuple of ints, got {shape!r}")
    return tuple(check_int(s, "shape entries", minimum=0) for s in shape)


def clutter(
    shape: Sequence[int],
    *,
    model: str = "exponential",
    looks: float = 1.0,
    shape_param: float | None = None,
    seed: int = 0,
    device: torch.device | str | None = None,
    dtype: torch.dtype = torch.float32,
) -> Tensor:
    """Draw unit-mean intensity clutter (texture times speckle) of any shape.

    See the module docstring for the exact parameterisation, moments and quantiles of each
    model; every model has ``E[I] = 1``.

    Args:
        shape: output shape, e.g. ``(B, 1, H, W)``; any number of dims, sizes >= 0.
        model: one of ``"exponential"``, ``"gamma"``, ``"k"``, ``"g0"``, ``"lognormal"``,
            ``"weibull"``.
        looks: number of looks ``L`` of the speckle (gamma, k, g0); must be 1 otherwise.
        shape_param: K: texture shape ``nu`` (default 2.0); G0: roughness ``a > 1`` (intensity
            G0 with ``alpha = -a``, default 3.0); lognormal: std ``s`` of ``ln I`` (default
            1.0); Weibull: shape ``c`` (default 0.8). Must be ``None`` for exponential/gamma.
        seed: seed in ``[0, 2**63)``; the same seed gives the same field.
        device: output device (default CPU); it must be available.
        dtype: ``torch.float32`` or ``torch.float64``.

    Returns:
        Tensor of ``shape``, non-negative, unit mean.

    Raises:
        OptionError: unknown model, invalid looks / shape_param / shape / seed, or a device
            that is not available.
        InputTypeError: unsupported dtype.

    Examples:
        >>> x = clutter((2, 1, 64, 64), model="gamma", looks=4.0, seed=1)
        >>> x.shape, x.dtype
        (torch.Size([2, 1, 64, 64]), torch.float32)
        >>> abs(float(x.mean()) - 1.0) < 0.05
        True
    """
    dims = _check_shape(shape)
    spec = clutter_spec(model, looks=looks, shape_param=shape_param)
    if dtype not in (torch.float32, torch.float64):
        raise InputTypeError(f"dtype must be torch.float32 or torch.float64, got {dtype}")
    generator = make_generator(check_seed(seed), check_device(device))
    return sample_clutter(spec, dims, generator, dtype)
