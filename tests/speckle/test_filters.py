"""Speckle filters: reference equality, fixed points, robustness, conventions, errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import torchsar as ts
from tests.reference.speckle import reference_batch
from tests.speckle._cases import DAMPED, NAMES, call, speckled
from torchsar.errors import (
    InputTypeError,
    InputValueError,
    OptionError,
    ShapeError,
    WindowSizeError,
)
from torchsar.speckle._local import Speckle, local_moments
from torchsar.windows import box_sums


@pytest.mark.parametrize("name", NAMES)
@settings(max_examples=12, deadline=None)
@given(
    window=st.sampled_from([3, 5, 7, 9, 11]),
    extra_h=st.integers(0, 9),
    extra_w=st.integers(0, 9),
    looks=st.floats(1.0, 16.0),
    sim_looks=st.sampled_from([0.5, 1.0, 4.0]),
    damping=st.floats(0.0, 4.0),
    seed=st.integers(0, 2**16),
)
def test_matches_reference(name, window, extra_h, extra_w, looks, sim_looks, damping, seed):
    """Every pixel (interior exact; border by the in-image rule) equals the per-pixel loop."""
    h, w = window + extra_h, window + extra_w
    x = speckled((1, 1, h, w), looks=sim_looks, seed=seed)
    got = call(name, x, window=window, looks=looks, damping=damping)
    want = reference_batch(name, x, window, looks, damping)
    np.testing.assert_allclose(got.numpy(), want, rtol=1e-9, atol=1e-12 * float(x.max()))


@pytest.mark.parametrize("looks", [1.0, 4.0])
def test_reference_cases_cover_every_class(looks):
    """The reference test images hold homogeneous, textured and point-like windows."""
    x = speckled((1, 1, 24, 24), looks=looks, seed=3)
    _, ci2 = local_moments(box_sums(x, 2))
    sp = Speckle(looks)
    assert bool((ci2 <= sp.cu2).any())
    assert bool(((ci2 > sp.cu2) & (ci2 < sp.cmax2)).any())
    assert bool((ci2 >= sp.cmax2).any())


def _hand_3x3(name: str, looks: float) -> float:
    """Centre of a 3x3 window of ones around a 9: mu = 17/9, Ci^2 = 512/289 (Ci = 1.33),
    damping 2. Textured for L = 1 (Cmax = 1.73), point-like for L = 4 (Cmax = 1.22)."""
    mu, ci2, i, damping = 17 / 9, 512 / 289, 9.0, 2.0
    ci, cu2, cmax = ci2**0.5, 1 / looks, (1 + 2 / looks) ** 0.5
    w_mmse = 1 - cu2 / ci2

    def frost_mean(a: float) -> float:
        e1, e2 = np.exp(-a), np.exp(-a * 2**0.5)
        return (i + 4 * e1 + 4 * e2) / (1 + 4 * e1 + 4 * e2)

    if name == "lee":
        return mu + w_mmse * (i - mu)
    if name == "kuan":
        return mu + w_mmse / (1 + cu2) * (i - mu)
    if name == "frost":
        return frost_mean(damping * ci2)
    if ci >= cmax:
        return i
    if name == "enhanced_lee":
        w = np.exp(-damping * (ci - cu2**0.5) / (cmax - ci))
        return mu * w + i * (1 - w)
    if name == "enhanced_frost":
        return frost_mean(damping * (ci - cu2**0.5) / (cmax - ci))
    a = (1 + cu2) / (ci2 - cu2)
    b = a - looks - 1
    return (b * mu + np.sqrt(b * b * mu * mu + 4 * a * looks * mu * i)) / (2 * a)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("looks", [1.0, 4.0])
def test_hand_computed_3x3(name, looks):
    x = torch.ones(1, 1, 3, 3, dtype=torch.float64)
    x[0, 0, 1, 1] = 9.0
    got = call(name, x, window=3, looks=looks, damping=2.0)[0, 0, 1, 1].item()
    assert got == pytest.approx(_hand_3x3(name, looks), rel=1e-12)
    if looks == 1.0:
        assert got == pytest.approx(359 / 72 if name == "lee" else got)  # 17/9 + 223/72


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("value", [0.0, 1e-3, 7.5, 1e6])
def test_constant_is_fixed_point(name, dtype, value):
    x = torch.full((2, 1, 12, 13), value, dtype=dtype)
    out = call(name, x, window=5, looks=3.0)
    rtol = 1e-6 if dtype == torch.float32 else 1e-12
    torch.testing.assert_close(out, x, rtol=rtol, atol=0.0)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("amplitude", [False, True])
def test_finite_on_degenerate_windows(name, amplitude):
    """Zero areas, constant areas, lone bright pixels and a huge dynamic range."""
    x = torch.zeros(4, 1, 15, 15, dtype=torch.float64)
    x[1] = 1.0
    x[2, 0, 7, 7] = 1.0  # one bright pixel among zeros
    x[3, 0, :, 8:] = 1e-20
    x[3, 0, 3, 3] = 1e15 if amplitude else 1e30  # intensity 1e30 fits float32
    for dtype in (torch.float32, torch.float64):
        out = call(name, x.to(dtype), window=7, looks=2.0, damping=3.0, amplitude=amplitude)
        assert bool(torch.isfinite(out).all())
        assert bool((out >= 0).all())
        assert out[0].abs().max().item() == 0.0


@pytest.mark.parametrize("name", NAMES)
def test_non_negative_and_smoothing(name):
    """Output >= 0 and, on homogeneous 1-look speckle, a lower variance than the input."""
    x = speckled((1, 1, 40, 40), looks=1.0, seed=5, dtype=torch.float32)
    flat = torch.empty(1, 1, 64, 64).exponential_(generator=torch.Generator().manual_seed(1))
    assert bool((call(name, x, window=5) >= 0).all())
    assert call(name, flat, window=5, damping=1.0).var() < 0.8 * flat.var()


@pytest.mark.parametrize("name", NAMES)
def test_batch_sizes(name):
    x = speckled((3, 2, 17, 19), looks=1.0, seed=7)
    full = call(name, x, window=5, looks=2.0)
    assert full.shape == x.shape
    for b in range(3):
        torch.testing.assert_close(
            call(name, x[b : b + 1], window=5, looks=2.0), full[b : b + 1], rtol=1e-12, atol=0
        )
    empty = call(name, x[:0], window=5)
    assert empty.shape == (0, 2, 17, 19)


@pytest.mark.parametrize("name", NAMES)
def test_dtype_and_non_contiguous(name):
    x = speckled((2, 1, 16, 18), looks=1.0, seed=11)
    assert call(name, x, window=3).dtype == torch.float64
    assert call(name, x.float(), window=3).dtype == torch.float32
    assert call(name, x.half(), window=3).dtype == torch.float32
    xt = x.transpose(-1, -2)
    assert not xt.is_contiguous()
    torch.testing.assert_close(call(name, xt, window=5), call(name, xt.contiguous(), window=5))
    torch.testing.assert_close(
        call(name, x.float(), window=5), call(name, x, window=5).float(), rtol=1e-4, atol=1e-5
    )


@pytest.mark.parametrize("name", NAMES)
def test_amplitude_option(name):
    a = speckled((1, 1, 14, 14), looks=1.0, seed=2).sqrt()
    got = call(name, a, window=5, amplitude=True)
    torch.testing.assert_close(got, call(name, a.square(), window=5).sqrt())


@pytest.mark.parametrize(
    ("cls", "name"),
    [
        (ts.speckle.Lee, "lee"),
        (ts.speckle.Kuan, "kuan"),
        (ts.speckle.EnhancedLee, "enhanced_lee"),
        (ts.speckle.Frost, "frost"),
        (ts.speckle.EnhancedFrost, "enhanced_frost"),
        (ts.speckle.GammaMAP, "gamma_map"),
    ],
)
def test_module_equals_function(cls, name):
    x = speckled((2, 1, 12, 12), looks=1.0, seed=4)
    opts = {"window": 5, "looks": 2.0}
    if name in DAMPED:
        opts["damping"] = 1.5
    torch.testing.assert_close(cls(**opts)(x), ts.speckle.FILTERS[name](x, **opts))
    assert "window=5" in repr(cls(**opts))


def test_frost_without_damping_is_box_mean():
    x = speckled((1, 1, 15, 16), looks=1.0, seed=8)
    want = box_sums(x, 3).mean()
    torch.testing.assert_close(ts.speckle.frost(x, window=7, damping=0.0), want)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize(
    ("x", "options", "error", "match"),
    [
        ([[1.0]], {}, InputTypeError, "x must be a torch.Tensor"),
        (torch.ones(8, 8), {}, ShapeError, r"\(B, C, H, W\)"),
        (torch.ones(1, 1, 8, 8, dtype=torch.complex64), {}, InputTypeError, "complex"),
        (torch.ones(1, 1, 8, 8, dtype=torch.int64), {}, InputTypeError, "floating"),
        (-torch.ones(1, 1, 8, 8), {}, InputValueError, "non-negative"),
        (torch.full((1, 1, 8, 8), float("nan")), {}, InputValueError, "finite"),
        (torch.ones(1, 1, 8, 8), {"window": 4}, OptionError, "window must be odd"),
        (torch.ones(1, 1, 8, 8), {"window": 1}, OptionError, "window must be >= 3"),
        (torch.ones(1, 1, 8, 8), {"window": 9}, WindowSizeError, "larger than the image"),
        (torch.ones(1, 1, 8, 8), {"looks": 0.0}, OptionError, "looks"),
        (torch.ones(1, 1, 8, 8), {"amplitude": 1}, OptionError, "amplitude must be a bool"),
    ],
)
def test_errors(name, x, options, error, match):
    with pytest.raises(error, match=match):
        ts.speckle.FILTERS[name](x, **options)


@pytest.mark.parametrize("name", DAMPED)
def test_negative_damping(name):
    with pytest.raises(OptionError, match="damping"):
        ts.speckle.FILTERS[name](torch.ones(1, 1, 8, 8), damping=-1.0)


def test_keyword_only():
    with pytest.raises(TypeError):
        ts.speckle.lee(torch.ones(1, 1, 8, 8), 3)  # type: ignore[misc]
