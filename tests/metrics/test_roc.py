from __future__ import annotations

import contextlib
import itertools
import math
import pickle
import struct

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from sklearn.metrics import roc_curve

from torchsar import _jit
from torchsar.errors import InputTypeError, InputValueError, ShapeError
from torchsar.metrics import RocAccumulator, pixel_counts, roc
from torchsar.metrics.roc import key_thresholds, pixel_keys

COMPILED = [True, False] if _jit.enabled() else [False]
MANTISSA_BITS = 5  # the key: the sign, 11 exponent bits and 5 mantissa bits (17 bits)
SHIFT = 64 - 1 - 11 - MANTISSA_BITS
RELATIVE = 2.0**-5  # the stated relative width of a key, for |x| >= SMALLEST_NORMAL
SUBNORMAL_WIDTH = 2.0**-1027  # the stated absolute width below it
SMALLEST_NORMAL = 2.0**-1022
INF_KEY = 2047 << MANTISSA_BITS


@contextlib.contextmanager
def _kernels(on: bool):
    """The compiled kernels switched on or off (no fixture: hypothesis tests use it too)."""
    before = _jit.ENABLED
    _jit.ENABLED = on
    try:
        yield
    finally:
        _jit.ENABLED = before


def _ref_key(x: float) -> int:
    """The key spelled out: float64 bits, -0.0 as +0.0, non-sign bits flipped below 0, top
    17 bits."""
    b = struct.unpack("<q", struct.pack("<d", float(x) + 0.0))[0]
    if b < 0:
        b ^= (1 << 63) - 1
    return b >> SHIFT


def _key(x: float) -> int:
    return int(pixel_keys(torch.tensor([x], dtype=torch.float64))[0])


def _data(seed, shape=(3, 1, 32, 32), dtype=torch.float32):
    """Statistics over many decades, both signs, zeros and infinities; targets, ignore."""
    g = torch.Generator().manual_seed(seed)
    target = torch.rand(shape, generator=g) < 0.2
    scale = 10.0 ** (torch.rand(shape, generator=g, dtype=torch.float64) * 24 - 12)
    stat = torch.randn(shape, generator=g, dtype=torch.float64) * scale + 3.0 * target
    flat = stat.view(-1)
    flat[:8] = torch.tensor([0.0, -0.0, math.inf, -math.inf, -math.inf, 1e-45, -1e-45, 3e38])
    ignore = torch.rand(shape, generator=g) < 0.1
    return stat.to(dtype), target, ignore


def _reference_curve(stat, target, ignore, thresholds):
    """``statistic > t`` counted directly for every threshold."""
    x = stat.double().numpy().ravel()
    t = target.numpy().ravel()
    care = np.ones_like(t) if ignore is None else ~ignore.numpy().ravel()
    above = x[:, None] > thresholds[None, :]
    hits_t = (above & (t & care)[:, None]).sum(0)
    hits_c = (above & (~t & care)[:, None]).sum(0)
    return hits_t, hits_c, int((t & care).sum()), int((~t & care).sum())


@pytest.mark.parametrize("compiled", COMPILED)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("with_ignore", [False, True])
def test_curve_equals_literal_exceedances(compiled, dtype, with_ignore):
    stat, target, ignore = _data(0, dtype=dtype)
    ignore = ignore if with_ignore else None
    with _kernels(compiled):
        acc = RocAccumulator()
        acc.update(stat, target, ignore)
    curve = acc.pixel_curve()
    thr = curve["threshold"]
    assert thr[0] == -np.inf and np.all(np.diff(thr) > 0)
    hits_t, hits_c, n_t, n_c = _reference_curve(stat, target, ignore, thr)
    assert (acc.targets, acc.clutter) == (n_t, n_c)
    np.testing.assert_array_equal(curve["pd_pixel"], hits_t / n_t)
    np.testing.assert_array_equal(curve["pfa_pixel"], hits_c / n_c)
    np.testing.assert_array_equal(acc.target_hits.numpy(), hits_t)
    np.testing.assert_array_equal(acc.clutter_hits.numpy(), hits_c)
    # one point per key present above -inf's, the first point every pixel above -inf
    x = stat.double().numpy().ravel()
    keep = np.ones(x.size, bool) if ignore is None else ~ignore.numpy().ravel()
    keys = {_ref_key(v) for v in x[keep & (x > -np.inf)]}
    assert thr.size == len(keys) + 1
    np.testing.assert_array_equal(acc.keys, sorted(keys))


def test_pixel_roc_matches_sklearn():
    """Values that are each their key's largest float: every distinct value is a point, and
    the curve is sklearn's (``score >= s`` there, ``score > t`` here, one value apart)."""
    g = torch.Generator().manual_seed(1)
    keys = torch.randint(-INF_KEY, INF_KEY, (2000,), generator=g).numpy()  # every finite key
    stat = torch.from_numpy(key_thresholds(keys))
    target = torch.rand(stat.shape, generator=g) < 0.3
    acc = RocAccumulator()
    acc.update(stat, target)
    fpr, tpr, _ = roc_curve(target.numpy(), stat.numpy(), drop_intermediate=False)
    curve = acc.pixel_curve()
    ours = sorted(zip(curve["pfa_pixel"], curve["pd_pixel"], strict=True))
    assert ours == sorted(zip(fpr, tpr, strict=True))


def _near_power(e: int, sign: float, step: float) -> float:
    """``sign * 2**e``, or its float neighbour up (``step`` 1) or down (-1)."""
    x = sign * math.ldexp(1.0, e)
    return math.nextafter(x, step * math.inf) if step else x


def _float64s():
    """Finite and infinite float64 values, subnormals, zeros and neighbours of powers of two."""
    powers = st.builds(
        _near_power,
        st.integers(-1074, 1023),
        st.sampled_from([1.0, -1.0]),
        st.sampled_from([1.0, -1.0, 0.0]),
    )
    return st.one_of(
        st.floats(allow_nan=False),
        powers,
        st.sampled_from([0.0, -0.0, math.inf, -math.inf, 5e-324, -5e-324]),
    )


def _float32s():
    return st.floats(allow_nan=False, width=32)


@settings(derandomize=True, max_examples=300, deadline=None)
@given(st.lists(st.one_of(_float64s(), _float32s()), min_size=2, max_size=20))
def test_keys_are_monotone_and_spelled_out(values):
    x = sorted(values)
    keys = pixel_keys(torch.tensor(x, dtype=torch.float64)).tolist()
    assert keys == [_ref_key(v) for v in x]
    assert keys == sorted(keys)
    with np.errstate(over="ignore"):
        f32 = [v for v in x if float(np.float32(v)) == v]
    if f32:
        k32 = pixel_keys(torch.tensor(f32, dtype=torch.float32)).tolist()
        assert k32 == [_ref_key(v) for v in f32]


@settings(derandomize=True, max_examples=300, deadline=None)
@given(st.one_of(_float64s(), _float32s()))
def test_a_threshold_is_the_largest_float_of_its_key(x):
    k = _key(x)
    t = float(key_thresholds(np.array([k]))[0])
    assert _key(t) == k and x <= t
    if t != math.inf:
        assert _key(math.nextafter(t, math.inf)) > k


def _lowest(k: int) -> float:
    """The smallest float64 of key ``k`` (a finite key)."""
    if k >= 0:
        return struct.unpack("<d", struct.pack("<q", k << SHIFT))[0]
    return -struct.unpack("<d", struct.pack("<q", ((~k + 1) << SHIFT) - 1))[0]


@settings(derandomize=True, max_examples=300, deadline=None)
@given(st.one_of(_float64s(), _float32s()).filter(math.isfinite))
def test_a_key_spans_at_most_the_stated_width(x):
    k = _key(x)
    lo, hi = _lowest(k), float(key_thresholds(np.array([k]))[0])
    assert _key(lo) == k and _key(math.nextafter(lo, -math.inf)) < k and lo <= x <= hi
    if min(abs(lo), abs(hi)) >= SMALLEST_NORMAL:
        assert hi - lo < RELATIVE * min(abs(lo), abs(hi))
    else:
        assert hi - lo < SUBNORMAL_WIDTH


def _span(k: int) -> tuple[float, float]:
    """The smallest and the largest float64 of key ``k``."""
    return _lowest(k), float(key_thresholds(np.array([k]))[0])


@pytest.mark.parametrize("e", [-1022, -149, -20, 0, 1, 52, 127, 1023])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_the_stated_widths_are_the_exact_bounds(e, sign):
    """A key starting at a power of two spans a relative width of ``2**-5`` less one float64
    unit of ``2**e``, so ``2**-5`` is the smallest bound; an octave holds ``2**5`` keys."""
    k = _key(sign * math.ldexp(1.0, e))
    lo, hi = _span(k)
    assert min(abs(lo), abs(hi)) == math.ldexp(1.0, e)
    assert (hi - lo) / math.ldexp(1.0, e) == RELATIVE - 2.0**-52
    up = math.ldexp(1.0, e + 1) if e < 1023 else math.inf  # inf: the key after 2**1023's
    assert abs(_key(sign * up) - k) == 2**MANTISSA_BITS


def test_the_subnormal_width_is_the_exact_bound():
    """The keys of ``|x| < 2**-1022`` span ``2**-1027`` less one subnormal unit (less two
    for the key just below 0, ``-0.0`` counting as ``+0.0``), and there are ``2**5`` of
    each sign."""
    last = _key(math.nextafter(SMALLEST_NORMAL, 0.0))
    assert last == 2**MANTISSA_BITS - 1 and _key(SMALLEST_NORMAL) == last + 1
    assert _key(-math.nextafter(SMALLEST_NORMAL, 0.0)) == -(2**MANTISSA_BITS)
    for k in (0, 1, last, -2, -last - 1):
        lo, hi = _span(k)
        assert hi - lo == SUBNORMAL_WIDTH - 5e-324
    assert _span(0) == (0.0, SUBNORMAL_WIDTH - 5e-324)
    assert _span(-1) == (-SUBNORMAL_WIDTH + 5e-324, -5e-324)


def test_the_key_constants_agree():
    assert roc.MANTISSA_BITS == MANTISSA_BITS and roc._SHIFT == SHIFT
    assert roc._INF_KEY == INF_KEY == _key(math.inf) == ~_key(-math.inf)
    assert _key(math.nextafter(math.inf, 0.0)) == INF_KEY - 1  # the largest finite key
    if _jit.enabled():
        from torchsar.metrics import _kernels

        assert _kernels.MANTISSA_BITS == MANTISSA_BITS and _kernels._SHIFT == SHIFT


def test_every_nonzero_float32_has_the_relative_resolution():
    assert float(np.finfo(np.float32).smallest_subnormal) >= SMALLEST_NORMAL


def test_huge_and_tiny_values_are_never_clipped():
    values = [-1e300, -1e6, -1e-300, 0.0, 1e-300, 1e-3, 1e6, 1e300, math.inf]
    assert len({_key(v) for v in values}) == len(values)
    stat = torch.tensor(values, dtype=torch.float64)
    target = torch.ones(stat.shape, dtype=torch.bool)
    acc = RocAccumulator()
    acc.update(stat, target)
    curve = acc.pixel_curve()
    assert curve["threshold"].size == len(values) + 1
    np.testing.assert_array_equal(curve["pd_pixel"] * len(values), np.arange(len(values), -1, -1))
    assert curve["threshold"][-2] >= 1e300 and curve["threshold"][-1] == math.inf


def test_neg_inf_and_ignored_pixels_count_only_where_they_should():
    stat = torch.tensor([[[[-torch.inf, 5.0, 0.5, 9.0]]]])
    target = torch.tensor([[[[False, True, False, False]]]])
    ignore = torch.tensor([[[[False, False, False, True]]]])
    acc = RocAccumulator()
    acc.update(stat, target, ignore)
    c = acc.pixel_curve()
    assert (acc.targets, acc.clutter) == (1, 2)
    assert c["threshold"][0] == -math.inf and c["threshold"].size == 3  # -inf, 0.5's, 5.0's
    assert c["pd_pixel"].tolist() == [1.0, 1.0, 0.0]
    assert c["pfa_pixel"].tolist() == [0.5, 0.0, 0.0]  # the -inf pixel exceeds nothing


def test_an_empty_accumulator_has_one_point():
    c = RocAccumulator().pixel_curve()
    assert c["threshold"].tolist() == [-math.inf] and c["pd_pixel"].tolist() == [0.0]


@settings(derandomize=True, max_examples=30, deadline=None)
@given(
    st.integers(0, 2**16),
    st.lists(st.integers(0, 3 * 32 * 32), max_size=5),
    st.randoms(use_true_random=False),
    st.sampled_from(COMPILED),
)
def test_merging_in_any_split_and_order_equals_one_pass(seed, cuts, rnd, compiled):
    stat, target, ignore = _data(seed)
    stat, target, ignore = stat.view(-1), target.view(-1), ignore.view(-1)
    with _kernels(compiled):
        whole = RocAccumulator()
        whole.update(stat, target, ignore)
        edges = [0, *sorted(cuts), stat.numel()]
        parts = []
        for a, b in itertools.pairwise(edges):
            part = RocAccumulator()
            part.update(stat[a:b], target[a:b], ignore[a:b])
            parts.append(part)
    rnd.shuffle(parts)
    merged = RocAccumulator()
    for part in parts:
        merged = merged + part if rnd.random() < 0.5 else part + merged
    assert merged == whole
    for k, v in whole.pixel_curve().items():
        np.testing.assert_array_equal(merged.pixel_curve()[k], v)


def test_updates_add_like_one_pass():
    stat, target, ignore = _data(2, shape=(4, 1, 32, 32))
    whole, parts = RocAccumulator(), RocAccumulator()
    whole.update(stat, target, ignore)
    for i in range(4):
        parts.update(stat[i : i + 1], target[i : i + 1], ignore[i : i + 1])
    assert parts == whole
    assert parts.keys.dtype == np.int32 and parts.target_counts.dtype == np.int64


@pytest.mark.parametrize("compiled", COMPILED)
def test_update_sparse_equals_update_on_the_dense_batch(compiled):
    stat, target, ignore = _data(3, dtype=torch.float64)
    g = torch.Generator().manual_seed(4)
    stat = stat.view(-1).masked_fill(torch.rand(stat.numel(), generator=g) < 0.7, -math.inf)
    target, ignore = target.view(-1), ignore.view(-1)
    idx = (stat > -math.inf).nonzero().squeeze(1)
    with _kernels(compiled):
        dense, sparse = RocAccumulator(), RocAccumulator()
        dense.update(stat, target, ignore)
        care = ~ignore
        n_target = int((target & care).sum())
        sparse.update_sparse(
            stat[idx], target[idx], ignore[idx], n_target, int(care.sum()) - n_target
        )
    assert sparse == dense


@pytest.mark.skipif(not _jit.enabled(), reason="numba kernels not available")
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("with_ignore", [False, True])
@pytest.mark.parametrize("seed", [5, 6])
def test_compiled_and_tensor_code_give_identical_states(dtype, with_ignore, seed):
    stat, target, ignore = _data(seed, shape=(2, 1, 64, 64), dtype=dtype)
    ignore = ignore if with_ignore else None
    out = []
    for on in (True, False):
        with _kernels(on):
            acc = RocAccumulator()
            acc.update(stat, target, ignore)
            acc.update(stat * 3, target, ignore)
            acc.update(torch.full_like(stat, math.inf), target, ignore)  # no finite value
            acc.update(stat[:0], target[:0])  # nothing at all
            out.append(acc)
    assert out[0] == out[1]


def test_float16_counts_like_its_exact_float32_values():
    stat, target, _ = _data(7)
    half = stat.clamp(-6e4, 6e4).half()
    a, b = RocAccumulator(), RocAccumulator()
    a.update(half, target)
    b.update(half.float(), target)
    assert a == b


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("with_ignore", [False, True])
@pytest.mark.parametrize("compiled", COMPILED)
def test_update_with_a_mask_returns_its_pixel_counts(dtype, with_ignore, compiled):
    stat, target, ignore = _data(8, dtype=dtype)
    ignore = ignore if with_ignore else None
    detected = stat > 1.0
    with _kernels(compiled):
        one, two = RocAccumulator(), RocAccumulator()
        got = one.update(stat, target, ignore, detected=detected)
        two.update(stat, target, ignore)
        assert RocAccumulator().update(stat, target, ignore) is None
    assert got == pixel_counts(detected, target, ignore=ignore)
    assert one == two


def test_update_validates():
    acc = RocAccumulator()
    with pytest.raises(InputTypeError, match="statistic"):
        acc.update(torch.zeros(1, 1, 2, 2, dtype=torch.int32), torch.zeros(1, 1, 2, 2) > 0)
    with pytest.raises(InputTypeError, match="target"):
        acc.update(torch.zeros(1, 1, 2, 2), torch.zeros(1, 1, 2, 2))
    with pytest.raises(ShapeError):
        acc.update(torch.zeros(1, 1, 2, 2), torch.zeros(1, 1, 2, 3, dtype=torch.bool))


@pytest.mark.parametrize("compiled", COMPILED)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_a_nan_is_refused_before_anything_is_added(compiled, dtype):
    stat = torch.tensor([[[[1.0, float("nan"), 3.0, -math.inf]]]], dtype=dtype)
    tgt = torch.zeros(1, 1, 1, 4, dtype=torch.bool)
    with _kernels(compiled):
        acc = RocAccumulator()
        with pytest.raises(InputValueError, match="NaN"):
            acc.update(stat, tgt, detected=stat > 0)
        with pytest.raises(InputValueError, match="NaN"):
            acc.update(stat, tgt)
        with pytest.raises(InputValueError, match="NaN"):
            acc.update_sparse(stat.view(-1), tgt.view(-1), tgt.view(-1), 0, 4)
    assert acc == RocAccumulator()
    with pytest.raises(InputTypeError, match="detected"):
        acc.update(stat.nan_to_num(), tgt, detected=stat)


def test_a_state_round_trips_and_an_old_grid_state_is_refused():
    stat, target, ignore = _data(9)
    acc = RocAccumulator()
    acc.update(stat, target, ignore)
    again = pickle.loads(pickle.dumps(acc))
    assert again == acc and again.pixel_curve()["threshold"].size == acc.keys.size + 1
    old = {
        "pixel_grid": torch.zeros(3),
        "target_hits": torch.zeros(3, dtype=torch.int64),
        "clutter_hits": torch.zeros(3, dtype=torch.int64),
        "targets": 0,
        "clutter": 0,
    }
    with pytest.raises(ValueError, match="not a RocAccumulator state"):
        RocAccumulator.__new__(RocAccumulator).__setstate__(old)
    unsorted = {**vars(acc), "keys": acc.keys[::-1].copy()}
    with pytest.raises(ValueError, match="keys and counts"):
        RocAccumulator.__new__(RocAccumulator).__setstate__(unsorted)


@pytest.mark.skipif(not _jit.enabled(), reason="numba kernels not available")
@pytest.mark.parametrize("spread", ["narrow", "signed", "zero and up"])
def test_dense_and_compact_tables_give_the_tensor_codes_counts(spread):
    """A batch whose key range fits a dense table and batches whose range spans zero (a
    table of only the exponents present): the compiled counts equal the tensor code's."""
    from torchsar.metrics import _kernels as roc_kernels

    g = torch.Generator().manual_seed(31)
    stat = torch.rand(2, 1, 40, 40, generator=g, dtype=torch.float64) * 9 + 1
    if spread == "signed":
        stat = stat * torch.randn(stat.shape, generator=g, dtype=torch.float64)
    elif spread == "zero and up":
        stat[0, 0, :5] = 0.0
        stat[1, 0, :3] = 1e-300
    target = torch.rand(stat.shape, generator=g) < 0.3
    ignore = torch.rand(stat.shape, generator=g) < 0.1
    flat = stat.reshape(-1).numpy()
    rows = roc_kernels._key(flat.max()) - roc_kernels._key(flat.min()) + 1
    assert (rows > roc_kernels._DENSE_ROWS) == (spread != "narrow")
    out = []
    for on in (True, False):
        with _kernels(on):
            acc = RocAccumulator()
            counts = acc.update(stat, target, ignore, detected=stat > 2.0)
            out.append((acc, counts))
    assert out[0][0] == out[1][0] and out[0][1] == out[1][1]
