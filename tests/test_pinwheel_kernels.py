"""The one-sweep kernels of GO-, SO- and VI-CFAR without no-data against the
integral-image tensor code they replace on CPU tensors and against slow references that
sum each block cell by cell: float32 statistics within an ulp, float64 within 1e-13 of the
exact sums (borders and degenerate planes included), masks equal wherever the statistic
is not within an ulp of the threshold, independent of the batch; the border and rule
factors are the tensor code's; the values are checked as they are read."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest
import torch

import torchsar.cfar as cfar
from tests.kernel_paths import both as _both
from tests.kernel_paths import ulps as _ulps
from tests.reference.cfar import block_reference, vi_statistic
from torchsar import _jit
from torchsar.cfar.blocks import block_scale, border_states
from torchsar.cfar.thresholds import block_factor
from torchsar.cfar.vi import rule_states
from torchsar.windows import pinwheel_rects, region_count

pytestmark = pytest.mark.skipif(not _jit.enabled(), reason="numba kernels not available")

DETECTORS = {"go": "max", "so": "min"}  # and the reduction of each
NAMES = [*DETECTORS, "vi"]


def _scene(seed: int, shape=(3, 2, 37, 45), dtype=torch.float32) -> torch.Tensor:
    """Exponential clutter with a bright target, a clutter edge and a plane of zeros."""
    g = torch.Generator().manual_seed(seed)
    x = torch.empty(shape, dtype=torch.float64).exponential_(generator=g)
    x[0, 0, 3:6, 4:8] *= 300.0
    x[-1, -1, :, shape[-1] // 2 :] *= 9.0
    if shape[0] > 1:
        x[1, 0] = 0.0  # 0 / 0 everywhere
    return x.to(dtype)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("dtype, ulps", [(torch.float32, 1.0), (torch.float64, 1e6)])
@pytest.mark.parametrize("guard, train", [(1, 3), (2, 4), (0, 1), (3, 2)])
def test_the_kernel_is_the_tensor_code_to_an_ulp(monkeypatch, name, dtype, ulps, guard, train):
    """float32: within an ulp; float64: within the integral images' own error."""
    x = _scene(1, dtype=dtype)
    fn = getattr(cfar, name)
    a, b = _both(monkeypatch, lambda: fn(x, guard=guard, train=train))
    assert a.statistic.dtype == b.statistic.dtype == dtype
    assert torch.equal(a.threshold, b.threshold)
    assert _ulps(a.statistic, b.statistic) <= ulps
    differ = a.mask != b.mask
    if bool(differ.any()):  # only where the statistic is within an ulp of the threshold
        near = (b.statistic.double() - b.threshold.double()).abs()
        assert bool((near[differ] <= 2 * np.spacing(np.float32(b.threshold))).all())


@pytest.mark.parametrize("name", list(DETECTORS))
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("guard, train", [(1, 2), (0, 3), (2, 1)])
def test_the_kernel_is_the_exactly_summed_statistic(monkeypatch, name, dtype, guard, train):
    """At every pixel, borders included, on planes the integral images get wrong (all
    zeros, one bright cell among zeros, a cell of 1e12 among ones)."""
    g = torch.Generator().manual_seed(2)
    x = torch.empty(1, 4, 11, 14, dtype=torch.float64).exponential_(generator=g)
    x[0, 1] = 0.0
    x[0, 2] = 0.0
    x[0, 2, 5, 6] = 50.0
    x[0, 3] = 1.0
    x[0, 3, 2, 3] = 1e12
    x = x.to(dtype)
    monkeypatch.setattr(_jit, "ENABLED", True)
    got = getattr(cfar, name)(x, guard=guard, train=train).statistic.double().numpy()
    want = block_reference(x.double().numpy(), guard, train, 1e-3, DETECTORS[name])
    assert np.array_equal(np.isinf(got), np.isinf(want))
    assert np.isinf(want).any() and (want == 0).any()  # the degenerate cases are there
    fin = np.isfinite(want)
    if dtype == torch.float32:
        ulp = np.spacing(np.abs(want[fin]).astype(np.float32)).astype(np.float64)
        assert (np.abs(got[fin] - want[fin]) <= ulp).all()
    else:
        np.testing.assert_allclose(got[fin], want[fin], rtol=1e-13, atol=0)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_vi_is_its_written_out_rule_at_every_pixel(monkeypatch, dtype):
    """Each pixel's rule, estimate and factor, borders included, on clutter with a bright
    patch (variable halves) and a clutter edge (differing means)."""
    rng = np.random.default_rng(8)
    img = rng.exponential(size=(2, 17, 19))
    img[0, 4:8, 5:9] *= 20.0
    img[1, :, 10:] *= 6.0
    x = torch.from_numpy(img)[:, None].to(dtype)
    monkeypatch.setattr(_jit, "ENABLED", True)
    got = cfar.vi(x, guard=1, train=2, k_vi=2.0, k_mr=1.5).statistic[:, 0].double().numpy()
    ones = np.ones(img.shape[1:], bool)
    want = np.array(
        [
            [
                [vi_statistic(a, ones, i, j, 1, 2, 1e-3, 2.0, 1.5) for j in range(19)]
                for i in range(17)
            ]
            for a in x[:, 0].double().numpy()
        ]
    )
    if dtype == torch.float32:
        ulp = np.spacing(np.abs(want).astype(np.float32)).astype(np.float64)
        assert (np.abs(got - want) <= ulp).all()
    else:
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)


@pytest.mark.parametrize("h, w, guard, train", [(9, 12, 1, 2), (20, 13, 2, 4), (14, 14, 0, 6)])
def test_the_rule_tables_are_the_tensor_codes_factors(h, w, guard, train):
    """``table[rule, rows[i], cols[j]]`` is :func:`torchsar.cfar.vi._rule_scale`'s factor of
    each pixel under each rule."""
    import importlib

    from torchsar.windows import Ring

    vimod = importlib.import_module("torchsar.cfar.vi")  # the module, not the function

    ring = Ring(guard, train)
    full = vimod.vi_threshold(guard=guard, train=train, pfa=1e-3, k_vi=4.76, k_mr=1.806)
    rows, cols, table = rule_states(h, w, guard, train, 1e-3, full)
    counts = [region_count(h, w, r) for r in pinwheel_rects(guard, train)]
    count_a, count_b = counts[0] + counts[1], counts[2] + counts[3]
    factor = partial(vimod._rule_factor, pfa=1e-3)
    maps = vimod._rule_maps(count_a, count_b, ring.n, full, factor)
    for rule in range(5):
        got = torch.from_numpy(table[rule][rows[:, None], cols[None, :]])
        assert torch.equal(got, maps[rule])


def test_the_kernel_keeps_its_precision_beside_a_very_bright_target(monkeypatch):
    """Clutter of 1 beside a cell of 1e12: exactly 1 / 1 where the target is not in a
    block (the integral image carries it into every later sum and cancels it out)."""
    x = torch.ones(1, 1, 64, 64, dtype=torch.float64)
    x[0, 0, 5, 5] = 1e12
    for name in DETECTORS:
        a, b = _both(monkeypatch, lambda name=name: getattr(cfar, name)(x, guard=1, train=2))
        far = a.statistic[0, 0, 20:-4, 20:-4]
        assert torch.equal(far, torch.ones_like(far))
        assert (b.statistic[0, 0, 20:-4, 20:-4] - 1).abs().max() < 1e-3


def test_the_mask_is_the_statistic_over_the_threshold():
    x = _scene(5)
    for name in NAMES:
        for pfa in (1e-1, 1e-3):
            d = getattr(cfar, name)(x, guard=1, train=3, pfa=pfa)
            assert d.threshold.dtype == x.dtype and d.threshold.dim() == 0
            assert d.mask.any() and torch.equal(d.mask, d.statistic > d.threshold)


def test_the_kernel_does_not_depend_on_the_batch_or_the_layout():
    x = _scene(4)
    for name in NAMES:
        fn = getattr(cfar, name)
        whole = fn(x).statistic
        for i in range(x.shape[0]):
            assert torch.equal(fn(x[i : i + 1]).statistic, whole[i : i + 1])
        wide = torch.cat([x, x], dim=-1)[..., : x.shape[-1]]  # a non-contiguous view
        assert torch.equal(fn(wide).statistic, whole)


def _sorted_factor(sizes: tuple[int, ...], reduce: str) -> float:
    return block_factor(tuple(sorted(sizes)), 1e-3, reduce)


@pytest.mark.parametrize("h, w, guard, train", [(9, 12, 1, 2), (20, 13, 2, 4), (14, 14, 0, 6)])
def test_the_border_table_is_the_tensor_codes_factors(h, w, guard, train):
    """``table[rows[i], cols[j]]`` is :func:`block_scale`'s factor of each pixel."""
    for reduce in ("max", "min"):
        rows, cols, table = border_states(h, w, guard, train, 1e-3, reduce)
        rects = pinwheel_rects(guard, train)
        counts = [region_count(h, w, r) for r in rects]
        interior = tuple(r.area for r in rects)
        factor = partial(_sorted_factor, reduce=reduce)
        want = block_scale(counts, interior, factor)
        got = torch.from_numpy(table[rows[:, None], cols[None, :]])
        assert torch.equal(got, torch.ones(h, w, dtype=torch.float64) if want is None else want)


BAD = {"nan": float("nan"), "inf": float("inf"), "-inf": float("-inf"), "negative": -1e-30}


@pytest.mark.parametrize("bad", list(BAD))
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_kernel_checks_the_values_as_it_reads_them(monkeypatch, bad, dtype):
    """A bad value in the first rows, inside, in the last row or in the last plane is
    refused with the tensor code's error, type and words."""
    from torchsar.errors import InputValueError

    for name in NAMES:
        for where in [(0, 0, 0, 0), (0, 1, 8, 7), (1, 1, 15, 13), (1, 0, 15, 0)]:
            x = _scene(6, shape=(2, 2, 16, 14), dtype=dtype)
            x[where] = BAD[bad]
            errors = []
            for on in (True, False):
                monkeypatch.setattr(_jit, "ENABLED", on)
                with pytest.raises(InputValueError) as err:
                    getattr(cfar, name)(x, guard=1, train=2)
                errors.append(str(err.value))
            assert errors[0] == errors[1]


def test_options_are_checked_before_the_values_on_both_paths(monkeypatch):
    from torchsar.errors import OptionError, WindowSizeError

    x = _scene(7, shape=(1, 1, 12, 12))
    x[0, 0, 6, 6] = float("nan")
    for name in NAMES:
        fn = getattr(cfar, name)
        for call, kind in [
            (lambda fn=fn: fn(x, guard=1, train=2, pfa=2.0), OptionError),
            (lambda fn=fn: fn(x, guard=4, train=4), WindowSizeError),
        ]:
            errors = []
            for on in (True, False):
                monkeypatch.setattr(_jit, "ENABLED", on)
                with pytest.raises(kind) as err:
                    call()
                errors.append(str(err.value))
            assert errors[0] == errors[1]


def test_an_empty_batch_is_valid():
    x = torch.zeros(0, 1, 16, 16)
    for name in NAMES:
        assert getattr(cfar, name)(x).statistic.shape == x.shape


@pytest.mark.parametrize("name", ["vi", "two_parameter"])
def test_a_bright_target_far_away_changes_nothing(name):
    """The kernels sum ``x`` and ``x^2`` as they are: a pixel whose windows do not reach a
    block of 1e12 gets the statistic it gets without it, bit for bit (sums of deviations
    from the plane's mean, which the block moves to 1e10, lost up to half the value)."""
    fn = getattr(cfar, name)
    x = torch.empty(1, 1, 40, 40, dtype=torch.float64).exponential_(
        generator=torch.Generator().manual_seed(26)
    )
    lit = x.clone()
    lit[0, 0, 34:39, 34:39] = 1e12
    far = (slice(None), slice(None), slice(0, 24), slice(0, 24))
    assert torch.equal(
        fn(lit, guard=1, train=2).statistic[far], fn(x, guard=1, train=2).statistic[far]
    )


@pytest.mark.parametrize("name", ["vi", "two_parameter"])
@pytest.mark.parametrize("factor", [2.0**600, 1e300, 1e-300])
def test_huge_and_tiny_float64_planes_give_the_scaled_statistic(name, factor):
    """Their statistics are ratios: a float64 plane scaled far up or down (its squares
    beyond float64's range) gives the statistic of the plane as it was, within rounding
    (the kernel divides such a plane by a power of two first)."""
    fn = getattr(cfar, name)
    x = torch.empty(2, 1, 12, 13, dtype=torch.float64).exponential_(
        generator=torch.Generator().manual_seed(27)
    )
    want = fn(x, guard=1, train=2)
    got = fn(x * factor, guard=1, train=2)
    torch.testing.assert_close(got.statistic, want.statistic, rtol=1e-12, atol=1e-12)
    assert torch.equal(got.mask, want.mask)


@pytest.mark.parametrize("name", list(DETECTORS))
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("guard, train", [(1, 2), (0, 3)])
def test_go_so_with_no_data_are_the_exactly_summed_statistic(
    monkeypatch, name, dtype, guard, train
):
    """With a valid mask the kernel sums and counts each block's valid cells: at every
    pixel the exactly summed statistic over them with the factor of the blocks' counts
    (degenerate planes, blocks without a valid cell, invalid pixels -inf); within an ulp of
    the tensor code on clutter; with a mask of all valid cells, of the unmasked kernel."""
    g = torch.Generator().manual_seed(5)
    x = torch.empty(1, 3, 13, 15, dtype=torch.float64).exponential_(generator=g)
    x[0, 1] = 0.0
    x[0, 1, 6, 7] = 50.0
    x[0, 2, 2, 3] = 1e12
    x = x.to(dtype)
    rng = np.random.default_rng(5)
    valid = rng.random(x.shape) > 0.3
    valid[0, 0, 2:12, 2:12] = False
    valid[0, 0, 7, 7] = True  # a valid pixel whose blocks hold no valid cell
    valid[0, 1, 6, 7] = True
    monkeypatch.setattr(_jit, "ENABLED", True)
    fn = getattr(cfar, name)
    d = fn(x, guard=guard, train=train, valid=torch.from_numpy(valid))
    got = d.statistic.double().numpy()
    want = block_reference(x.double().numpy(), guard, train, 1e-3, DETECTORS[name], valid)
    assert np.array_equal(got[~np.isfinite(want)], want[~np.isfinite(want)])
    assert want[0, 0, 7, 7] == -np.inf and (want == 0).any()
    fin = np.isfinite(want)
    if dtype == torch.float32:
        ulp = np.spacing(np.abs(want[fin]).astype(np.float32)).astype(np.float64)
        assert (np.abs(got[fin] - want[fin]) <= ulp).all()
    else:
        np.testing.assert_allclose(got[fin], want[fin], rtol=1e-13, atol=1e-300)
    assert torch.equal(d.mask, d.statistic > d.threshold)
    clutter = _scene(6, dtype=dtype)
    mask = torch.rand(clutter.shape, generator=torch.Generator().manual_seed(6)) > 0.2
    a, b = _both(monkeypatch, lambda: fn(clutter, guard=guard, train=train, valid=mask))
    assert _ulps(a.statistic, b.statistic) <= (1.0 if dtype == torch.float32 else 1e6)
    monkeypatch.setattr(_jit, "ENABLED", True)
    ones = torch.ones_like(clutter, dtype=torch.bool)
    plain = fn(clutter, guard=guard, train=train).statistic
    assert _ulps(fn(clutter, guard=guard, train=train, valid=ones).statistic, plain) <= 1.0
