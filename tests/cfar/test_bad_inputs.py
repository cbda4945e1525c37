"""Inputs at the edge of the CFAR family's domain: a correct result or a typed error."""

from __future__ import annotations

import pytest
import torch
from scipy import stats

import torchsar as ts
from torchsar.cfar.thresholds import block_factor, ca_factor
from torchsar.errors import InputTypeError, OptionError

DETECTORS = [n for n in ts.cfar.__all__ if n not in ("Detection", "detection_from", "threshold")]


def _image(dtype=torch.float32):
    x = torch.empty(1, 1, 24, 24).exponential_(generator=torch.Generator().manual_seed(0))
    return x.to(dtype)


@pytest.mark.parametrize("name", [*DETECTORS, "region_cfar"])
def test_input_requiring_grad_is_refused_with_the_fix(name):
    fn = ts.region.region_cfar if name == "region_cfar" else getattr(ts.cfar, name)
    x = _image().requires_grad_()
    with pytest.raises(InputTypeError, match=rf"x requires grad; {name} is not .*x\.detach\(\)"):
        fn(x)


@pytest.mark.parametrize("pfa", [1e-17, 1e-30, 1e-300])
def test_two_parameter_tiny_pfa_has_the_exact_finite_threshold(pfa):
    want = stats.norm.isf(pfa)
    assert ts.cfar.threshold("two_parameter", pfa=pfa) == pytest.approx(want, rel=1e-12)
    assert float(ts.cfar.two_parameter(_image(torch.float64), pfa=pfa).threshold) == pytest.approx(
        want, rel=1e-12
    )


def test_block_factor_tiny_pfa_exact_or_refused():
    # a single block is CA: the closed form checks the log-domain integration far in the tail
    assert block_factor((16,), 1e-30, "max") == pytest.approx(ca_factor(16, 1e-30), rel=1e-9)
    with pytest.raises(OptionError, match="pfa=1e-300 is too small for the GO threshold"):
        block_factor((16,), 1e-300, "max")


@pytest.mark.parametrize("name", ["go", "so"])
def test_go_so_pfa_1e300_never_a_math_error(name):
    try:
        thr = ts.cfar.threshold(name, pfa=1e-300)
    except OptionError as e:
        assert "pfa=1e-300" in str(e)
    else:
        assert thr > ts.cfar.threshold(name, pfa=1e-30) and thr < float("inf")


@pytest.mark.parametrize("looks", [0.001, 0.05, 2.5])
def test_ca_factor_small_looks_matches_the_f_quantile_or_is_refused(looks):
    n, pfa = 144, 1e-3
    want = stats.f.isf(pfa, 2 * looks, 2 * n * looks)  # I / mean_ring ~ F(2L, 2NL)
    try:
        got = ca_factor(n, pfa, looks)
    except OptionError as e:
        assert f"looks={looks:g}" in str(e)
        assert not want < 1e300  # only refused where there is no finite quantile
    else:
        assert got == pytest.approx(want, rel=1e-9)


@pytest.mark.parametrize("name", ["ca", "gamma"])
def test_tiny_looks_without_a_finite_threshold_is_a_typed_error(name):
    with pytest.raises(OptionError, match="looks=1e-06 gives no finite threshold"):
        getattr(ts.cfar, name)(_image(), looks=1e-6)


@pytest.mark.parametrize("dtype", [torch.bfloat16, torch.float16])
@pytest.mark.parametrize("name", ["os", "ca", "go", "two_parameter"])
def test_low_precision_input_computes_in_float32(name, dtype):
    fn = getattr(ts.cfar, name)
    low = fn(_image(dtype))
    ref = fn(_image(dtype).float())
    assert low.statistic.dtype == torch.float32
    assert torch.equal(low.statistic, ref.statistic)


@pytest.mark.parametrize("name", DETECTORS)
@pytest.mark.parametrize("compiled", [True, False])
def test_options_are_checked_before_the_values(monkeypatch, name, compiled):
    """Every CFAR detector, with or without its compiled kernels: a bad option beside a bad
    value gives the option's error (the values are checked last, where a kernel reads
    them or before the sums)."""
    from torchsar import _jit
    from torchsar.errors import WindowSizeError

    monkeypatch.setattr(_jit, "ENABLED", compiled)
    fn = getattr(ts.cfar, name)
    x = _image()
    x[0, 0, 12, 12] = float("nan")
    with pytest.raises(OptionError, match="pfa"):
        fn(x, pfa=2.0)
    with pytest.raises(WindowSizeError):
        fn(x, guard=8, train=8)
