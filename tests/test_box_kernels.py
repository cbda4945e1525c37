"""The one-sweep window kernels (CA-CFAR's ring-mean ratio; the Lee, Kuan, enhanced Lee,
Frost and enhanced Frost filters) against the integral-image tensor code they replace on CPU tensors and against
slow references: float32 results within an ulp or two, masks equal wherever the statistic
is not within an ulp of the threshold, exact where the sums are exact (flat images),
independent of the batch; closer to the exact sums than the tensor code where contrast
makes integral images cancel."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest
import torch

import torchsar.cfar as cfar
import torchsar.speckle as speckle
from tests.kernel_paths import both as _both
from tests.kernel_paths import errors as _errors
from tests.kernel_paths import ulps as _ulps
from tests.reference.cfar import (
    ac_reference,
    ca_reference,
    two_parameter_reference,
    zero_blocks_scene,
)
from tests.reference.speckle import reference_batch
from torchsar import _jit
from torchsar.cfar.ca import ca_threshold
from torchsar.windows import Ring, region_count, ring_counts

pytestmark = pytest.mark.skipif(not _jit.enabled(), reason="numba kernels not available")


def _scene(seed: int, shape=(3, 2, 37, 45), dtype=torch.float32) -> torch.Tensor:
    """Exponential clutter with a bright target and a clutter edge."""
    g = torch.Generator().manual_seed(seed)
    x = torch.empty(shape, dtype=torch.float64).exponential_(generator=g)
    x[0, 0, 3:6, 4:8] *= 300.0  # a target
    x[-1, -1, :, shape[-1] // 2 :] *= 9.0  # a clutter edge
    return x.to(dtype)


def _degenerate(seed: int, dtype=torch.float64) -> torch.Tensor:
    """Planes the integral images get wrong: all zeros (0 / 0), one bright cell among
    zeros (its ring holds only zeros: inf), a cell of 1e12 among ones."""
    x = _scene(seed, shape=(1, 4, 11, 14), dtype=torch.float64)
    x[0, 1] = 0.0
    x[0, 2] = 0.0
    x[0, 2, 5, 6] = 50.0
    x[0, 3] = 1.0
    x[0, 3, 2, 3] = 1e12
    return x.to(dtype)


def _finite_near(got: np.ndarray, want: np.ndarray, dtype, *, rtol: float, atol: float) -> None:
    """Where ``want`` is finite: ``got`` within a float32 ulp of it (float32), else within
    ``rtol`` / ``atol``."""
    fin = np.isfinite(want)
    if dtype == torch.float32:
        ulp = np.spacing(np.abs(want[fin]).astype(np.float32)).astype(np.float64)
        assert (np.abs(got[fin] - want[fin]) <= ulp).all()
    else:
        np.testing.assert_allclose(got[fin], want[fin], rtol=rtol, atol=atol)


def _masks_agree(a, b) -> None:
    """Equal masks, except at pixels whose statistic is within an ulp of the threshold."""
    differ = a.mask != b.mask
    if bool(differ.any()):
        thr = b.threshold.double()
        near = (b.statistic.double() - thr).abs() <= 2 * np.spacing(np.float32(thr))
        assert bool(near[differ].all())


# float64 results: within the integral images' own error (float64 ulps of the window's sum)
@pytest.mark.parametrize("dtype, ulps", [(torch.float32, 1.0), (torch.float64, 1e4)])
@pytest.mark.parametrize("guard, train", [(2, 4), (0, 1), (1, 3), (3, 2), (2, 7)])
def test_ca_is_the_tensor_code_to_an_ulp(monkeypatch, dtype, ulps, guard, train):
    x = _scene(1, dtype=dtype)
    a, b = _both(monkeypatch, lambda: cfar.ca(x, guard=guard, train=train))
    assert a.statistic.dtype == b.statistic.dtype == dtype
    assert _ulps(a.statistic, b.statistic) <= ulps
    _masks_agree(a, b)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_compiled_mask_is_the_statistic_over_the_threshold(monkeypatch, dtype):
    """The kernel decides as it writes the statistic: the same mask as ``statistic >
    threshold`` on the returned tensors, the threshold a scalar of the statistic's dtype."""
    monkeypatch.setattr(_jit, "ENABLED", True)
    x = _scene(5, dtype=dtype)
    for pfa in (1e-1, 1e-3):
        d = cfar.ca(x, guard=1, train=3, pfa=pfa)
        assert d.threshold.dtype == dtype and d.threshold.dim() == 0
        want = torch.tensor(ca_threshold(guard=1, train=3, pfa=pfa, looks=1.0), dtype=dtype)
        assert torch.equal(d.threshold, want)
        assert d.mask.dtype == torch.bool and d.mask.any()
        assert torch.equal(d.mask, d.statistic > d.threshold)


def test_ac_without_no_data_is_the_tensor_code_to_an_ulp(monkeypatch):
    x = _scene(2)
    a, b = _both(monkeypatch, lambda: cfar.ac(x, guard=1, train=3))
    assert _ulps(a.statistic, b.statistic) <= 1.0
    _masks_agree(a, b)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("guard, train", [(1, 2), (0, 3)])
def test_ca_is_the_exactly_summed_statistic_borders_included(monkeypatch, dtype, guard, train):
    """At every pixel, borders and degenerate planes included: float32 within an ulp of the
    exactly summed statistic, float64 within 1e-13 of it."""
    x = _degenerate(3, dtype)
    monkeypatch.setattr(_jit, "ENABLED", True)
    got = cfar.ca(x, guard=guard, train=train).statistic.double().numpy()
    want = ca_reference(x.double().numpy(), guard, train, 1e-3)
    assert np.array_equal(np.isinf(got), np.isinf(want))
    assert np.isinf(want).any() and (want == 0).any()  # the degenerate cases are there
    _finite_near(got, want, dtype, rtol=1e-13, atol=0)


@pytest.mark.parametrize(
    "guard, train", [(0, 1), (2, 4), (2, 7), (1, 15), (5, 20), (3, 31), (7, 63), (0, 2)]
)
def test_the_fold_in_the_dividing_loop_is_the_ring_sum_bit_for_bit(guard, train):
    """CA's kernel adds the last terms of each ring sum in the loop that divides
    (``ring_fold_plan``: a head folded first when there are more than four terms): on
    random levels, head then tail make the very additions of ``ring_sums``' two block-sum
    calls, in their order (every sum equal bit for bit), for windows of few and of many
    blocks."""
    from torchsar import _box_kernels as bk
    from torchsar._block_sums import block_sums

    w = 23
    band, mid, levels = bk.ring_buffers(guard, train, w)
    levels[:-2] = np.random.default_rng(guard * 100 + train).exponential(size=levels[:-2].shape)
    o = guard + train
    want = np.zeros(w)
    block_sums(band, 0, 2 * o + 1, (0,), w, want, False)
    block_sums(mid, 0, train, (0, o + guard + 1), w, want, True)
    head, tail = bk.ring_fold_plan(guard, train, band.shape[0], mid.shape[0])
    terms = _terms(o, train)
    assert tail.shape == (4, 4) and len(head) == (terms - 3 if terms > 4 else 0)
    bk.fold_head(levels, head, w)
    got = np.zeros(w)
    for k, (r0, p0, r1, p1) in enumerate(tail):
        term = levels[r0, p0 : p0 + w] + levels[r1, p1 : p1 + w]
        got = term if k == 0 else got + term
    assert np.array_equal(got.view(np.int64), want.view(np.int64))


def _terms(o: int, train: int) -> int:
    """How many pair terms the ring's two block-sum calls add: the band's blocks in pairs,
    then the middle rows' (both sides) in pairs."""
    band, side = bin(2 * o + 1).count("1"), bin(train).count("1")
    return (band + 1) // 2 + side


def test_ca_keeps_its_precision_beside_a_very_bright_target(monkeypatch):
    """Clutter of 1 beside cells of 1e12: the integral image carries the target into every
    later sum and cancels it back out; the direct sums never add it where it is not."""
    x = torch.ones(1, 1, 64, 64, dtype=torch.float64)
    x[0, 0, 5, 5] = 1e12
    a, b = _both(monkeypatch, lambda: cfar.ca(x, guard=1, train=2).statistic)
    far = a[0, 0, 20:-4, 20:-4]
    assert torch.equal(far, torch.ones_like(far))  # exactly 1 / 1 where the target is not
    assert (b[0, 0, 20:-4, 20:-4] - 1).abs().max() < 1e-3  # the tensor code: near 1


def test_ca_does_not_depend_on_the_batch_or_the_layout():
    x = _scene(4)
    whole = cfar.ca(x).statistic
    for i in range(x.shape[0]):
        assert torch.equal(cfar.ca(x[i : i + 1]).statistic, whole[i : i + 1])
    wide = torch.cat([x, x], dim=-1)[..., : x.shape[-1]]  # a non-contiguous view
    assert torch.equal(cfar.ca(wide).statistic, whole)


def test_ring_counts_are_the_counts_that_occur():
    for h, w, ring in [(9, 9, Ring(1, 2)), (20, 13, Ring(2, 4)), (13, 13, Ring(0, 6))]:
        want = set(region_count(h, w, ring.region).long().flatten().tolist())
        assert ring_counts(h, w, ring) == want


def test_an_empty_batch_is_valid():
    x = torch.zeros(0, 1, 16, 16)
    assert cfar.ca(x).statistic.shape == x.shape
    assert speckle.lee(x).shape == x.shape


FILTERS = ["lee", "kuan", "enhanced_lee", "frost", "enhanced_frost"]


def _filter(name: str):
    """The filter, with damping 1 where it has one (the reference's)."""
    fn = getattr(speckle, name)
    return fn if name in ("lee", "kuan") else partial(fn, damping=1.0)


def _speckle_reference(name: str, x: torch.Tensor, amplitude: bool) -> np.ndarray:
    """The reference filter of the intensity the filter sees (amplitude squared in the
    input's dtype), in float64."""
    img = (x.square() if amplitude else x).double().numpy()
    want = reference_batch(name, img, 5, 2.0, 1.0)
    return np.sqrt(np.maximum(want, 0)) if amplitude else want


@pytest.mark.parametrize("name", FILTERS)
@pytest.mark.parametrize("amplitude", [False, True])
@pytest.mark.parametrize("make", [_scene, _degenerate])
def test_speckle_filters_are_the_reference(monkeypatch, name, amplitude, make):
    """float64: within 1e-12 of the pixel-by-pixel reference; float32 input: within an ulp
    of it (the kernel works in float64 and casts once). Beside a target 300 times brighter
    than the clutter the integral images of the tensor code are off by ~1e-10."""
    monkeypatch.setattr(_jit, "ENABLED", True)
    fn = _filter(name)
    x64 = make(5).double()[:1, :, :20, :23]  # small: the reference loops over every pixel
    want = _speckle_reference(name, x64, amplitude)
    got = fn(x64, window=5, looks=2.0, amplitude=amplitude).numpy()
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-300)
    x32 = x64.float()
    want32 = _speckle_reference(name, x32, amplitude)
    got32 = fn(x32, window=5, looks=2.0, amplitude=amplitude).double().numpy()
    ulp = np.spacing(np.abs(want32).astype(np.float32)).astype(np.float64)
    assert (np.abs(got32 - want32) <= ulp).all()


@pytest.mark.parametrize("name", ["frost", "enhanced_frost"])
@pytest.mark.parametrize("window", [7, 17])
def test_frost_weights_as_powers_are_the_reference(monkeypatch, name, window):
    """One ``exp`` per square-free base and powers for its multiples (window 7: 5 of 9
    shells' ``exp``); window 17 has a multiple that skips one (distance 10 = (6, 8) without
    9 = (0, 9)), which takes an ``exp`` of its own. Within 1e-12 of the reference."""
    from torchsar.speckle.frost import _power_table

    bases, base_of, multiple = _power_table(window // 2)
    if window == 7:
        assert len(bases) == 5 and len(base_of) == 9
    else:
        chained = [
            m == 1 or m - 1 in multiple[:k][base_of[:k] == b]
            for k, (b, m) in enumerate(zip(base_of, multiple, strict=True))
        ]
        assert not all(chained)
    monkeypatch.setattr(_jit, "ENABLED", True)
    x = _scene(6, dtype=torch.float64)[:1, :1, :20, :23]
    x[0, 0, 9, 11] = 40.0  # a bright cell: large decays beside it
    want = reference_batch(name, x.numpy(), window, 2.0, 1.0)
    got = _filter(name)(x, window=window, looks=2.0).numpy()
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("name", FILTERS)
def test_the_tensor_code_is_still_the_reference(monkeypatch, name):
    """The fallback (other devices, autograd, no numba) within its own integral-image error."""
    monkeypatch.setattr(_jit, "ENABLED", False)
    x = _scene(5).double()
    got = _filter(name)(x, window=5, looks=2.0).numpy()
    np.testing.assert_allclose(got, _speckle_reference(name, x, False), rtol=1e-8)


@pytest.mark.parametrize("name", FILTERS)
def test_speckle_filters_keep_flat_images_and_huge_planes(monkeypatch, name):
    monkeypatch.setattr(_jit, "ENABLED", True)
    fn = getattr(speckle, name)
    flat = torch.full((2, 1, 9, 11), 3.25)
    assert torch.equal(fn(flat, window=3), flat)  # zero variance, exactly
    x = _scene(7)
    huge = fn(x * 2.0**100, window=5)  # squares would overflow float32: scaled, exactly
    assert torch.equal(huge, fn(x, window=5) * 2.0**100)
    assert torch.isfinite(huge).all()


@pytest.mark.parametrize("name", FILTERS)
def test_speckle_filters_do_not_depend_on_the_batch(name):
    x = _scene(8)
    fn = getattr(speckle, name)
    whole = fn(x, window=7)
    for i in range(x.shape[0]):
        assert torch.equal(fn(x[i : i + 1], window=7), whole[i : i + 1])


def test_gradients_still_flow_through_the_tensor_code():
    x = _scene(9)[:1].requires_grad_(True)
    speckle.lee(x, window=3).sum().backward()
    assert x.grad is not None and torch.isfinite(x.grad).all()


def test_the_vectorised_exp_is_exp():
    from torchsar._vector_exp import exp_neg

    x = -np.concatenate([np.linspace(0, 707.9, 20001), np.geomspace(1e-300, 1, 301)])
    got = np.array([exp_neg(v) for v in x])
    np.testing.assert_allclose(got, np.exp(x), rtol=4e-16, atol=0)
    assert [exp_neg(v) for v in (0.0, -0.0, -708.5, -1e6, -np.inf)] == [1.0, 1.0, 0, 0, 0]


BAD = {"nan": float("nan"), "inf": float("inf"), "-inf": float("-inf"), "negative": -1e-30}


@pytest.mark.parametrize("name", FILTERS)
@pytest.mark.parametrize("bad", list(BAD))
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_kernels_check_the_values_as_they_read_them(monkeypatch, name, bad, dtype):
    """The kernels check every value as they read it instead of a scan beforehand: a bad
    value in the first rows, the last row or the last plane is refused with the same
    typed error and words as the tensor code gives."""
    from torchsar.errors import InputValueError

    fn = getattr(speckle, name)
    for where in [(0, 0, 0, 0), (0, 0, 1, 5), (1, 1, 15, 13), (1, 0, 15, 0)]:
        x = _scene(11, shape=(2, 2, 16, 14), dtype=dtype)
        x[where] = BAD[bad]
        messages = []
        for on in (True, False):
            monkeypatch.setattr(_jit, "ENABLED", on)
            with pytest.raises(InputValueError) as err:
                fn(x, window=5)
            messages.append(str(err.value))
        assert messages[0] == messages[1]


def test_an_infinite_peak_is_reported_as_given_not_as_rescaled(monkeypatch):
    """float64 planes are rescaled by a power of two before the kernel (against overflow of
    the squares); the error names the input's own counts of NaN and Inf."""
    from torchsar.errors import InputValueError

    monkeypatch.setattr(_jit, "ENABLED", True)
    x = _scene(12, shape=(1, 1, 12, 12), dtype=torch.float64)
    x[0, 0, 3, 3] = float("inf")
    x[0, 0, 5, 5] = 1.7e308  # doubled by a rescale it would be inf too
    with pytest.raises(InputValueError, match="0 NaN and 1 Inf"):
        speckle.lee(x, window=3)


@pytest.mark.parametrize("name", ["enhanced_lee", "enhanced_frost"])
def test_the_enhanced_classes_are_the_tensor_codes_on_their_borders(monkeypatch, name):
    """A corner pixel's window of four cells, one bright among zeros, has ``Ci^2 = 3``:
    exactly ``Cmax^2`` at one look, a point target (the observation kept) on every path,
    with damping 0 too (no weight to blur a misplaced class)."""
    fn = getattr(speckle, name)
    rng = np.random.default_rng(13)
    for bright in [12.437085151672363, *rng.uniform(0.1, 100.0, size=40).tolist()]:
        x = torch.zeros(1, 1, 4, 4)
        x[0, 0, 0, 0] = bright
        a, b = _both(monkeypatch, lambda x=x: fn(x, window=3, looks=1.0, damping=0.0))
        assert a[0, 0, 0, 0] == b[0, 0, 0, 0] == x[0, 0, 0, 0]


def _border_moments(rng, cu: float, cmax: float, n: float, size: int):
    """Window means and variances whose ``Ci`` lies on, within a few ulps of, or well off
    the class borders ``Cu``, ``Cmax`` and the clamp ``sqrt(n - 1)``; zero and tiny means."""
    mu = rng.uniform(1e-3, 1e3, size) * 10.0 ** rng.integers(-30, 30, size)
    borders = np.array([cu, cmax, np.sqrt(n - 1.0)])
    ci = borders[rng.integers(0, 3, size)]
    steps = rng.integers(-3, 4, size)  # a few ulps either side
    ci = np.where(steps > 0, np.nextafter(ci, np.inf), np.where(steps < 0, np.nextafter(ci, 0), ci))
    off = rng.random(size) < 0.4  # anywhere in [0, sqrt(n - 1)] instead
    ci = np.where(off, rng.uniform(0.0, np.sqrt(n - 1.0), size), ci)
    var = (ci * mu) ** 2
    mu[:4], var[:4] = [0.0, 0.0, 1e-160, 2.0**-500], [0.0, 1.0, 1e-318, 2.0**-999]
    return mu, var


@pytest.mark.parametrize("looks", [1.0, 3.0])
@pytest.mark.parametrize("n", [4.0, 9.0, 49.0])
def test_the_quick_heterogeneity_is_the_heterogeneity_or_doubts(looks, n):
    """One division and one square root instead of two and one: outside its doubtful
    pixels the class of every pixel is the exact formula's and ``h`` within ``2^-50``
    of it plus the cancellation both incur beside a border; at least the doubtful pixels
    are those on a border, near the clamp or with a mean of 0 or below ``2^-480``."""
    from torchsar._moment_kernels import heterogeneity, quick_heterogeneity

    cu, cmax = 1.0 / np.sqrt(looks), np.sqrt(1.0 + 2.0 / looks)
    mu, var = _border_moments(np.random.default_rng(int(n * looks)), cu, cmax, n, 4000)
    for damping in (0.0, 1.0, 5.0):
        for m, v in zip(mu.tolist(), var.tolist(), strict=True):
            h, doubt = quick_heterogeneity(m, v, n, cu, cmax, damping)
            if doubt:
                continue
            want = heterogeneity(m, v, n, cu, cmax, damping)
            ci = np.sqrt(v) / m
            assert ci > 0 and min(abs(ci - cu), abs(ci - cmax)) > 2.0**-41 * ci
            assert (h == 0) == (want == 0) and (h == np.inf) == (want == np.inf)
            if 0 < want < np.inf:
                cancel = ci / min(abs(ci - cu), abs(ci - cmax))
                assert abs(h - want) <= 2.0**-50 * (1.0 + cancel) * want
    doubts = [quick_heterogeneity(m, v, n, cu, cmax, 1.0)[1] for m, v in zip(mu, var, strict=True)]
    assert all(doubts[:4])
    ci = np.sqrt(var[4:]) / mu[4:]
    on = np.isin(ci, [cu, cmax, np.sqrt(n - 1.0)])
    assert np.asarray(doubts[4:])[on].all() and on.any()


def test_a_bad_option_and_a_bad_value_give_one_error_on_both_paths(monkeypatch):
    """The values are checked after the options whether or not a kernel reads them."""
    from torchsar.errors import OptionError, WindowSizeError

    x = _scene(14, shape=(1, 1, 9, 9))
    x[0, 0, 4, 4] = float("nan")
    small = _scene(14, shape=(1, 1, 4, 4))
    small[0, 0, 0, 0] = -1.0
    cases = [
        (lambda: speckle.lee(x, window=4), OptionError),
        (lambda: speckle.frost(x, looks=0), OptionError),
        (lambda: speckle.enhanced_frost(x, damping=-1.0), OptionError),
        (lambda: speckle.kuan(small, window=5), WindowSizeError),
    ]
    for call, kind in cases:
        on, off = _errors(monkeypatch, call)
        assert on == off and on[0] is kind


@pytest.mark.parametrize("name", FILTERS)
def test_a_tiny_negative_beside_a_huge_peak_is_refused(monkeypatch, name):
    """float64 planes whose peak exceeds 2^384 are divided by a power of two before the
    kernel; a negative value that this would underflow to -0.0 is refused as given."""
    from torchsar.errors import InputValueError

    x = _scene(15, shape=(1, 1, 9, 9), dtype=torch.float64)
    x[0, 0, 0, 0] = 1e300
    x[0, 0, 8, 8] = -1e-300
    on, off = _errors(monkeypatch, lambda: getattr(speckle, name)(x, window=3))
    assert on == off and on[0] is InputValueError and "-1e-300" in on[1]


def test_a_lazily_negated_view_is_read_as_its_values(monkeypatch):
    """``conj().imag`` of a complex tensor is a view with torch's negation bit set."""
    b = _scene(16, shape=(1, 1, 10, 12))
    view = torch.complex(torch.zeros_like(b), -b).conj().imag
    assert view.is_neg() and torch.equal(view, b)
    on_view, off_view = _both(monkeypatch, lambda: speckle.lee(view, window=3))
    on, off = _both(monkeypatch, lambda: speckle.lee(b, window=3))
    assert torch.equal(on_view, on) and torch.equal(off_view, off)


@pytest.mark.parametrize("name", ["ca", "two_parameter", "ac"])
@pytest.mark.parametrize("bad", list(BAD))
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_ring_kernels_check_the_values_as_they_read_them(monkeypatch, name, bad, dtype):
    """The kernels check every value as they read it instead of a scan beforehand: a bad
    value in the first rows (read before the first output row), inside, in the last row
    or in the last plane is refused with the tensor code's error, type and words."""
    from torchsar.errors import InputValueError

    fn = getattr(cfar, name)
    for where in [(0, 0, 0, 0), (0, 0, 1, 5), (0, 1, 8, 7), (1, 1, 15, 13), (1, 0, 15, 0)]:
        x = _scene(17, shape=(2, 2, 16, 14), dtype=dtype)
        x[where] = BAD[bad]
        on, off = _errors(monkeypatch, lambda x=x: fn(x, guard=1, train=2))
        assert on == off and on[0] is InputValueError


def test_ca_checks_its_options_before_the_values_on_both_paths(monkeypatch):
    """A call with a bad option and a bad value gets the option's error with or without
    the kernel."""
    from torchsar.errors import OptionError, WindowSizeError

    x = _scene(18, shape=(1, 1, 12, 12))
    x[0, 0, 6, 6] = float("nan")
    cases = [
        (lambda: cfar.ca(x, guard=1, train=2, pfa=2.0), OptionError),
        (lambda: cfar.ca(x, guard=1, train=2, looks=0.0), OptionError),
        (lambda: cfar.ca(x, guard=4, train=4), WindowSizeError),
    ]
    for call, kind in cases:
        on, off = _errors(monkeypatch, call)
        assert on == off and on[0] is kind


def test_ca_reads_a_lazily_negated_view_as_its_values(monkeypatch):
    """``conj().imag`` of a complex tensor is a view with torch's negation bit set."""
    b = _scene(19, shape=(1, 1, 14, 12))
    view = torch.complex(torch.zeros_like(b), -b).conj().imag
    assert view.is_neg() and torch.equal(view, b)
    on_view, off_view = _both(monkeypatch, lambda: cfar.ca(view, guard=1, train=2))
    on, off = _both(monkeypatch, lambda: cfar.ca(b, guard=1, train=2))
    for got, want in [(on_view, on), (off_view, off)]:
        assert torch.equal(got.statistic, want.statistic) and torch.equal(got.mask, want.mask)


@pytest.mark.parametrize("dtype, ulps", [(torch.float32, 1.0), (torch.float64, 1e7)])
@pytest.mark.parametrize("guard, train", [(1, 3), (2, 4), (0, 1), (3, 2)])
def test_two_parameter_is_the_tensor_code_to_an_ulp(monkeypatch, dtype, ulps, guard, train):
    """float32 within an ulp; float64 within the integral images' own error."""
    x = _scene(20, dtype=dtype)
    a, b = _both(monkeypatch, lambda: cfar.two_parameter(x, guard=guard, train=train))
    assert a.statistic.dtype == b.statistic.dtype == dtype
    assert torch.equal(a.threshold, b.threshold)
    assert _ulps(a.statistic, b.statistic) <= ulps
    _masks_agree(a, b)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("guard, train", [(1, 2), (0, 3), (2, 1)])
def test_two_parameter_is_the_exactly_summed_statistic(monkeypatch, dtype, guard, train):
    """At every pixel, borders and degenerate planes included (all zeros, one bright cell
    among zeros, a cell of 1e12 among ones: rings without variance give +inf, -inf or 0)."""
    x = _degenerate(21, dtype)
    monkeypatch.setattr(_jit, "ENABLED", True)
    got = cfar.two_parameter(x, guard=guard, train=train).statistic.double().numpy()
    want = two_parameter_reference(x.double().numpy(), guard, train)
    assert np.array_equal(got[~np.isfinite(want)], want[~np.isfinite(want)])
    assert np.isinf(want).any() and (want == 0).any()  # the degenerate cases are there
    _finite_near(got, want, dtype, rtol=1e-12, atol=1e-300)


def test_two_parameter_rings_without_variance_are_exact(monkeypatch):
    """A flat patch of any value in clutter: its rings have no variance, so a pixel above
    the patch's value is +inf, one below -inf, one at it 0 (sums of deviations from the
    plane's mean leave a rounding residue; the kernel sums those rings again from their
    own cells)."""
    monkeypatch.setattr(_jit, "ENABLED", True)
    rng = np.random.default_rng(22)
    for trial, c in enumerate(rng.uniform(0.01, 100.0, size=40)):
        dtype = torch.float64 if trial % 2 else torch.float32
        x = torch.rand(1, 1, 32, 32, generator=torch.Generator().manual_seed(trial)) * 10
        x = x.to(dtype)
        x[0, 0, 5:20, 5:20] = float(c)
        x[0, 0, 12, 12] = float(c) * 2
        x[0, 0, 16, 12] = float(c) / 2
        s = cfar.two_parameter(x, guard=1, train=2).statistic[0, 0]
        assert s[12, 12] == torch.inf and s[16, 12] == -torch.inf and s[8, 16] == 0


def test_two_parameter_checks_its_options_before_the_values_on_both_paths(monkeypatch):
    from torchsar.errors import OptionError, WindowSizeError

    x = _scene(24, shape=(1, 1, 12, 12))
    x[0, 0, 6, 6] = float("nan")
    cases = [
        (lambda: cfar.two_parameter(x, guard=1, train=2, pfa=2.0), OptionError),
        (lambda: cfar.two_parameter(x, guard=1, train=2, k=-1.0), OptionError),
        (lambda: cfar.two_parameter(x, guard=4, train=4), WindowSizeError),
    ]
    for call, kind in cases:
        on, off = _errors(monkeypatch, call)
        assert on == off and on[0] is kind


def test_two_parameter_does_not_depend_on_the_batch_or_the_layout():
    x = _scene(25)
    d = cfar.two_parameter(x, guard=1, train=3, pfa=1e-2)
    assert d.mask.any() and torch.equal(d.mask, d.statistic > d.threshold)
    for i in range(x.shape[0]):
        assert torch.equal(
            cfar.two_parameter(x[i : i + 1], guard=1, train=3).statistic, d.statistic[i : i + 1]
        )
    wide = torch.cat([x, x], dim=-1)[..., : x.shape[-1]]  # a non-contiguous view
    assert torch.equal(cfar.two_parameter(wide, guard=1, train=3).statistic, d.statistic)
    assert cfar.two_parameter(torch.zeros(0, 1, 16, 16)).statistic.shape == (0, 1, 16, 16)


def _censored(seed: int, dtype=torch.float32) -> torch.Tensor:
    """Clutter with bright rows and targets that the global pre-threshold censors, a
    patch where whole rings are censored, and a plane of zeros."""
    x = _scene(seed, shape=(2, 2, 30, 33), dtype=torch.float64)
    x[0, 0, 5, 3:20] *= 500.0  # a bright row: censored out of the rings it crosses
    x[0, 1, 10:25, 10:25] = 1e4  # rings wholly censored: the global ratio
    x[1, 0] = 0.0
    return x.to(dtype)


# float64: within the integral images' own error (1e6 ulps, 2e-10: their sums carry the
# 1e4 patch and the bright row; the exactly summed reference below bounds the kernel)
@pytest.mark.parametrize("dtype, ulps", [(torch.float32, 1.0), (torch.float64, 1e6)])
@pytest.mark.parametrize("guard, train", [(1, 3), (2, 4), (0, 1)])
def test_ac_is_the_tensor_code_to_an_ulp(monkeypatch, dtype, ulps, guard, train):
    x = _censored(30, dtype)
    a, b = _both(monkeypatch, lambda: cfar.ac(x, guard=guard, train=train))
    assert a.statistic.dtype == b.statistic.dtype == dtype
    assert torch.equal(a.threshold, b.threshold)
    assert _ulps(a.statistic, b.statistic) <= ulps
    _masks_agree(a, b)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("guard, train, clutter_mean", [(1, 2, None), (0, 3, None), (2, 1, 0.7)])
def test_ac_is_the_exactly_summed_statistic(monkeypatch, dtype, guard, train, clutter_mean):
    """At every pixel, borders, censored rows, wholly censored rings and a plane of zeros
    included; the pre-threshold as :func:`torchsar.cfar.ac.global_censor_threshold` (or
    the given clutter mean) sets it."""
    import math

    from torchsar.cfar.ac import global_censor_threshold

    x = _censored(31, dtype)
    monkeypatch.setattr(_jit, "ENABLED", True)
    d = cfar.ac(x, guard=guard, train=train, clutter_mean=clutter_mean)
    if clutter_mean is None:
        mu, limit = global_censor_threshold(x, 1e-3)
        mu, limit = mu[..., 0, 0].numpy(), limit[..., 0, 0].numpy()
    else:
        mu = np.full(x.shape[:2], clutter_mean)
        limit = mu * math.log(1.0 / 1e-3)
    want = ac_reference(x.double().numpy(), guard, train, 1e-3, limit, mu)
    got = d.statistic.double().numpy()
    assert np.array_equal(got[~np.isfinite(want)], want[~np.isfinite(want)])
    _finite_near(got, want, dtype, rtol=1e-13, atol=1e-300)


def test_ac_does_not_depend_on_the_batch_or_the_layout():
    x = _censored(33)
    d = cfar.ac(x, guard=1, train=3, pfa=1e-2)
    assert d.mask.any() and torch.equal(d.mask, d.statistic > d.threshold)
    for i in range(x.shape[0]):
        one = cfar.ac(x[i : i + 1], guard=1, train=3, pfa=1e-2).statistic
        assert torch.equal(one, d.statistic[i : i + 1])
    wide = torch.cat([x, x], dim=-1)[..., : x.shape[-1]]  # a non-contiguous view
    assert torch.equal(cfar.ac(wide, guard=1, train=3, pfa=1e-2).statistic, d.statistic)
    assert cfar.ac(torch.zeros(0, 1, 16, 16)).statistic.shape == (0, 1, 16, 16)


def test_every_kernel_sets_its_own_fastmath():
    """numba compiles a helper that sets no fastmath with its first caller's flags: the
    moments would take FMAs when the Frost kernel compiled them first and none when a Lee
    filter did, and the results would depend on which filter ran first."""
    import importlib

    from numba.core.registry import CPUDispatcher

    names = ["_block_sums", "_moment_kernels", "_box_kernels", "_shell_kernels", "_vector_exp"]
    names.append("_pinwheel_kernels")
    seen = 0
    for name in names:
        mod = importlib.import_module(f"torchsar.{name}")
        for value in vars(mod).values():
            if isinstance(value, CPUDispatcher) and value.__module__ == mod.__name__:
                assert "fastmath" in value.targetoptions, f"{name}.{value.__name__}"
                seen += 1
    assert seen > 20


def test_two_parameter_flat_rings_in_the_corners_are_exact(monkeypatch):
    """A near-flat ring is summed again from its own cells, never from the cell under test
    or another guard cell (in a corner the window's first cell is one): pixels equal to
    their constant ring give 0, as the written-out statistic does."""
    monkeypatch.setattr(_jit, "ENABLED", True)
    for value, corner, dtype in [(0.1, 0.7, torch.float64), (1 / 3, 5.0, torch.float32)]:
        x = torch.full((1, 1, 9, 9), value, dtype=dtype)
        x[0, 0, 0, 0] = corner
        got = cfar.two_parameter(x, guard=2, train=2, k=3.0).statistic.double().numpy()
        want = two_parameter_reference(x.double().numpy(), 2, 2)
        exact = (want == 0) | np.isinf(want)  # the flat rings: 0 at their value
        assert exact.sum() > 40 and np.array_equal(got[exact], want[exact])
        np.testing.assert_allclose(got[~exact], want[~exact], rtol=1e-6)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("guard, train", [(1, 2), (0, 3)])
def test_two_parameter_with_no_data_is_the_exactly_summed_statistic(
    monkeypatch, dtype, guard, train
):
    """With a valid mask the kernel sums and counts the ring's valid cells: at every pixel
    the exactly summed statistic over them (degenerate planes, whole invalid blocks, rings
    without a valid cell and invalid pixels, which are -inf, included)."""
    x = _degenerate(23, dtype)
    rng = np.random.default_rng(23)
    valid = rng.random(x.shape) > 0.25
    valid[0, 0, 2:11, 2:11] = False
    valid[0, 0, 6, 6] = True  # a valid pixel whose ring holds no valid cell
    monkeypatch.setattr(_jit, "ENABLED", True)
    d = cfar.two_parameter(x, guard=guard, train=train, valid=torch.from_numpy(valid))
    got = d.statistic.double().numpy()
    want = two_parameter_reference(x.double().numpy(), guard, train, valid)
    assert np.array_equal(got[~np.isfinite(want)], want[~np.isfinite(want)])
    assert want[0, 0, 6, 6] == -np.inf and (want == np.inf).any() and (want == 0).any()
    _finite_near(got, want, dtype, rtol=1e-12, atol=1e-300)
    assert torch.equal(d.mask, d.statistic > d.threshold)


def test_two_parameter_with_no_data_is_the_tensor_code_on_clutter(monkeypatch):
    """On clutter, masked: within an ulp of the tensor code's integral images (float32);
    the same with a mask of all valid cells as without a mask, bit for bit; independent of
    the batch."""
    x = _scene(24, dtype=torch.float32)
    valid = torch.rand(x.shape, generator=torch.Generator().manual_seed(24)) > 0.2
    a, b = _both(monkeypatch, lambda: cfar.two_parameter(x, guard=1, train=3, valid=valid))
    assert _ulps(a.statistic, b.statistic) <= 1.0
    _masks_agree(a, b)
    monkeypatch.setattr(_jit, "ENABLED", True)
    ones = torch.ones_like(x, dtype=torch.bool)
    plain = cfar.two_parameter(x, guard=1, train=3)
    assert torch.equal(
        cfar.two_parameter(x, guard=1, train=3, valid=ones).statistic, plain.statistic
    )
    for i in range(x.shape[0]):
        one = cfar.two_parameter(x[i : i + 1], guard=1, train=3, valid=valid[i : i + 1])
        assert torch.equal(one.statistic, a.statistic[i : i + 1])
    shared = valid[:1, :1]  # one mask for every image and channel
    whole = cfar.two_parameter(x, guard=1, train=3, valid=shared).statistic
    assert torch.equal(
        whole[1:2], cfar.two_parameter(x[1:2], guard=1, train=3, valid=shared).statistic
    )


def test_two_parameter_with_no_data_beside_blocks_of_zeros(monkeypatch):
    """Blocks of zeros and targets up to 1e12 times the clutter: the masked kernel (a mask
    of all valid cells) gives the direct sums' detections; the tensor code's integral
    images of deviations from the plane's mean disagreed on hundreds of pixels."""
    monkeypatch.setattr(_jit, "ENABLED", True)
    for seed in range(8):
        rng = np.random.default_rng(seed)
        h, w = (int(v) for v in rng.integers(24, 48, 2))
        img = zero_blocks_scene(rng, h, w)
        x = torch.from_numpy(img).to(torch.float32 if seed % 2 else torch.float64)
        ones = torch.ones_like(x, dtype=torch.bool)
        direct = cfar.two_parameter(x, guard=1, train=2)
        masked = cfar.two_parameter(x, guard=1, train=2, valid=ones)
        assert torch.equal(masked.mask, direct.mask) and torch.equal(
            masked.statistic, direct.statistic
        )


@pytest.mark.parametrize("name", ["two_parameter", "ca", "ac"])
def test_the_no_data_kernels_refuse_bad_values_anywhere(monkeypatch, name):
    """A NaN in an invalid cell is still refused, with the tensor code's words."""
    from torchsar.errors import InputValueError

    x = _scene(25, dtype=torch.float32)[:1]
    valid = torch.ones_like(x, dtype=torch.bool)
    x[0, 0, 5, 5] = float("nan")
    valid[0, 0, 5, 5] = False
    errs = _errors(monkeypatch, lambda: getattr(cfar, name)(x, valid=valid))
    assert errs[0] == errs[1] and errs[0][0] is InputValueError


def _no_data(x: torch.Tensor, seed: int) -> np.ndarray:
    """A no-data mask: random invalid cells, an invalid block, inside it a valid pixel whose
    ring holds no valid cell (for guard 1 or less and train 3 or less); the bright cell
    among zeros of :func:`_degenerate` valid (its statistic inf)."""
    rng = np.random.default_rng(seed)
    valid = rng.random(x.shape) > 0.25
    valid[0, 0, 2:11, 2:11] = False
    valid[0, 0, 6, 6] = True
    if x.shape[1] > 2:
        valid[0, 2, 5, 6] = True
    return valid


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("guard, train", [(1, 2), (0, 3)])
def test_ca_with_no_data_is_the_exactly_summed_statistic(monkeypatch, dtype, guard, train):
    """With a valid mask the one-sweep kernel sums and counts the ring's valid cells: at
    every pixel the exactly summed statistic over them with the border rule's factor for
    their count (degenerate planes, rings without a valid cell and invalid pixels, which
    are -inf, included); within an ulp of the tensor code on clutter."""
    x = _degenerate(41, dtype)
    valid = _no_data(x, 41)
    monkeypatch.setattr(_jit, "ENABLED", True)
    d = cfar.ca(x, guard=guard, train=train, valid=torch.from_numpy(valid))
    got = d.statistic.double().numpy()
    want = ca_reference(x.double().numpy(), guard, train, 1e-3, valid)
    assert np.array_equal(got[~np.isfinite(want)], want[~np.isfinite(want)])
    assert want[0, 0, 6, 6] == -np.inf and (want == np.inf).any() and (want == 0).any()
    _finite_near(got, want, dtype, rtol=1e-13, atol=1e-300)
    assert torch.equal(d.mask, d.statistic > d.threshold)
    clutter = _scene(42, dtype=dtype)
    mask = torch.rand(clutter.shape, generator=torch.Generator().manual_seed(42)) > 0.2
    a, b = _both(monkeypatch, lambda: cfar.ca(clutter, guard=guard, train=train, valid=mask))
    assert _ulps(a.statistic, b.statistic) <= (1.0 if dtype == torch.float32 else 1e4)
    _masks_agree(a, b)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_ac_with_no_data_is_the_exactly_summed_statistic(monkeypatch, dtype):
    """AC with a valid mask: the censored ring's valid cells summed and counted, a ring
    with none kept taking the global ratio, invalid pixels -inf; the pre-threshold from the
    valid pixels (:func:`torchsar.cfar.ac.global_censor_threshold`)."""
    from torchsar.cfar.ac import global_censor_threshold

    x = _censored(43, dtype)
    valid = _no_data(x, 43)
    monkeypatch.setattr(_jit, "ENABLED", True)
    mask = torch.from_numpy(valid)
    d = cfar.ac(x, guard=1, train=2, valid=mask)
    mu, limit = global_censor_threshold(x, 1e-3, valid=mask)
    mu, limit = mu[..., 0, 0].numpy(), limit[..., 0, 0].numpy()
    want = ac_reference(x.double().numpy(), 1, 2, 1e-3, limit, mu, valid)
    got = d.statistic.double().numpy()
    assert np.array_equal(got[~np.isfinite(want)], want[~np.isfinite(want)])
    assert (want == -np.inf).any()
    _finite_near(got, want, dtype, rtol=1e-13, atol=1e-300)
    assert torch.equal(d.mask, d.statistic > d.threshold)


@pytest.mark.parametrize("name", ["ca", "ac"])
def test_a_mask_of_all_valid_cells_changes_nothing(monkeypatch, name):
    """The masked kernel with every cell valid gives the unmasked statistic bit for bit,
    and each image of a batch its own (one mask shared by the batch, or one per image)."""
    monkeypatch.setattr(_jit, "ENABLED", True)
    x = _scene(44)
    detector = getattr(cfar, name)
    plain = detector(x, guard=1, train=3).statistic
    ones = torch.ones_like(x, dtype=torch.bool)
    assert torch.equal(detector(x, guard=1, train=3, valid=ones).statistic, plain)
    valid = torch.rand(x.shape, generator=torch.Generator().manual_seed(44)) > 0.2
    whole = detector(x, guard=1, train=3, valid=valid).statistic
    for i in range(x.shape[0]):
        one = detector(x[i : i + 1], guard=1, train=3, valid=valid[i : i + 1]).statistic
        assert torch.equal(one, whole[i : i + 1])
    shared = valid[:1, :1]
    both = detector(x, guard=1, train=3, valid=shared).statistic
    assert torch.equal(both[1:2], detector(x[1:2], guard=1, train=3, valid=shared).statistic)


def _ring_moments(x: np.ndarray, guard: int, train: int, r0: int, rows: int, valid=None):
    from torchsar import _box_kernels

    p_, _, w = x.shape
    count, mean, var = (np.empty((p_, rows, w)) for _ in range(3))
    flags = np.ones((1, 1, 1), np.uint8) if valid is None else valid.astype(np.uint8)
    _box_kernels.ring_moments(x, flags, valid is not None, guard, train, r0, count, mean, var)
    return count, mean, var


@pytest.mark.parametrize("masked", [False, True])
@pytest.mark.parametrize("guard, train, r0, rows", [(1, 2, 0, 20), (0, 3, 7, 6), (2, 1, 15, 5)])
def test_ring_moments_are_the_exact_moments(masked, guard, train, r0, rows):
    """Signed values (logarithms), strips of rows, masks: each pixel's ring count, mean and
    population variance within float64 ulps of the exactly summed ones; a ring of equal
    cells has a variance of exactly 0."""
    import math

    from tests.reference.cfar import ring_cells

    rng = np.random.default_rng(guard + 3 * train + r0)
    x = np.log(rng.exponential(size=(2, 20, 23)))
    x[1, 4:16, 4:18] = -0.3  # equal cells: near-flat rings
    valid = rng.random(x.shape) > 0.25 if masked else None
    count, mean, var = _ring_moments(x, guard, train, r0, rows, valid)
    for p in range(2):
        ok = None if valid is None else np.where(valid[p], 1.0, np.nan)
        for i in range(r0, r0 + rows):
            for j in range(23):
                cells = ring_cells(x[p], i, j, guard, train)
                if ok is not None:
                    cells = cells[~np.isnan(ring_cells(ok, i, j, guard, train))]
                n = len(cells)
                assert count[p, i - r0, j] == n
                if n == 0:
                    continue
                m = math.fsum(cells) / n
                v = math.fsum((cells - m) ** 2) / n
                assert abs(mean[p, i - r0, j] - m) <= 1e-14 * (1 + abs(m))
                assert abs(var[p, i - r0, j] - v) <= 1e-13 * (v + m * m)
                if (cells == cells[0]).all():
                    assert var[p, i - r0, j] == 0.0 and mean[p, i - r0, j] == cells[0]


@pytest.mark.parametrize("name", ["lognormal", "weibull", "gamma", "k", "g0"])
def test_distribution_cfars_on_the_ring_moments_kernel(monkeypatch, name):
    """The distribution CFARs take the ring moments kernel on the CPU: within a float32 ulp
    or two of the tensor code (the K and G0 laws' shape fits amplify an ulp: 1e-4), with
    and without no-data, and whatever the batch."""
    x = _scene(50)
    valid = torch.rand(x.shape, generator=torch.Generator().manual_seed(50)) > 0.2
    fn = getattr(cfar, name)
    for mask in (None, valid):
        a, b = _both(monkeypatch, lambda m=mask: fn(x, valid=m))
        fin = torch.isfinite(b.statistic)
        assert torch.equal(torch.isfinite(a.statistic), fin)
        tol = 1e-4 if name in ("k", "g0") else 3e-7
        assert torch.allclose(a.statistic[fin], b.statistic[fin], rtol=tol, atol=0)
    monkeypatch.setattr(_jit, "ENABLED", True)
    whole = fn(x).statistic
    assert torch.equal(fn(x[1:2]).statistic, whole[1:2])
