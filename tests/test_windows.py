from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from tests.reference.windows import rect_cells, ring_cells
from torchsar import _jit, windows
from torchsar.windows import Rect, Region, Ring, pinwheel_rects, rect_sums, ring_sums, windowed


def _image(seed: int, h: int, w: int, b: int = 1) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.empty(b, 1, h, w, dtype=torch.float64).exponential_(generator=g)


@given(
    guard=st.integers(0, 3),
    train=st.integers(1, 3),
    extra=st.integers(0, 6),
    seed=st.integers(0, 10_000),
)
def test_ring_sums_match_brute_force_everywhere(guard, train, extra, seed):
    o = guard + train
    h, w = 2 * o + 1 + extra, 2 * o + 3 + extra // 2
    x = _image(seed, h, w)
    s = ring_sums(x, guard, train)
    mean, var = s.mean()[0, 0], s.var()[0, 0]
    img = x[0, 0].numpy()
    for i in range(h):
        for j in range(w):
            cells = ring_cells(img, i, j, guard, train)
            assert s.count[..., i, j].item() == cells.size
            np.testing.assert_allclose(mean[i, j].item(), cells.mean(), rtol=1e-12)
            np.testing.assert_allclose(var[i, j].item(), cells.var(), rtol=1e-9, atol=1e-12)


@given(seed=st.integers(0, 10_000), guard=st.integers(0, 2), train=st.integers(1, 3))
def test_valid_mask_excludes_cells(seed, guard, train):
    x = _image(seed, 12, 11)
    g = torch.Generator().manual_seed(seed + 1)
    valid = torch.rand(1, 1, 12, 11, generator=g) > 0.3
    s = ring_sums(x, guard, train, valid=valid)
    img, v = x[0, 0].numpy(), valid[0, 0].numpy()
    for i in range(12):
        for j in range(11):
            cells = ring_cells(img, i, j, guard, train, v)
            assert s.count[0, 0, i, j].item() == cells.size
            if cells.size:
                np.testing.assert_allclose(s.mean()[0, 0, i, j].item(), cells.mean(), rtol=1e-12)


@given(guard=st.integers(0, 3), train=st.integers(1, 4))
def test_pinwheel_tiles_ring_exactly(guard, train):
    ring = set(map(tuple, Ring(guard, train).offsets().tolist()))
    seen: list[tuple[int, int]] = []
    for r in pinwheel_rects(guard, train):
        assert r.area == train * (2 * guard + train + 1)
        seen += [(a, b) for a in range(r.r0, r.r1 + 1) for b in range(r.c0, r.c1 + 1)]
    assert len(seen) == len(set(seen)) == Ring(guard, train).n
    assert set(seen) == ring


def test_pinwheel_block_sums_match_brute_force():
    x = _image(3, 15, 16)
    sums = rect_sums(x, pinwheel_rects(2, 3))
    img = x[0, 0].numpy()
    for s, r in zip(sums, pinwheel_rects(2, 3), strict=True):
        for i, j in [(0, 0), (7, 8), (14, 15), (3, 12)]:
            cells = rect_cells(img, i, j, r.r0, r.r1, r.c0, r.c1)
            assert s.count[0, 0, i, j].item() == cells.size
            np.testing.assert_allclose(
                s.s1[0, 0, i, j] + cells.size * s.shifts()[0, 0, i, j], cells.sum(), rtol=1e-12
            )


def test_ring_geometry():
    ring = Ring(2, 4)
    assert ring.n == 13 * 13 - 5 * 5 == len(ring.offsets())
    assert ring.region.area == ring.n
    with pytest.raises(ValueError, match="train"):
        Ring(1, 0)


@pytest.mark.parametrize("strip", [1, 3, 7, None])
def test_strips_do_not_change_results(strip):
    x = _image(0, 20, 9, b=2)
    full = windowed(x, [Rect.box(2)], lambda xs, s: s[0].mean(), strip=None)
    part = windowed(x, [Rect.box(2)], lambda xs, s: s[0].mean(), strip=strip)
    torch.testing.assert_close(part, full, rtol=1e-13, atol=0)


def test_batch_size_invariant_bitwise():
    x = _image(5, 64, 48, b=5)
    whole = ring_sums(x, 2, 3)
    for i in range(5):
        one = ring_sums(x[i : i + 1], 2, 3)
        assert torch.equal(one.s1, whole.s1[i : i + 1])
        assert torch.equal(one.s2, whole.s2[i : i + 1])


def test_constant_image_has_zero_variance_exactly():
    x = torch.full((1, 1, 30, 30), 1234.5678, dtype=torch.float32)
    s = ring_sums(x, 1, 3)
    assert torch.all(s.var() == 0)
    assert torch.allclose(s.mean(), torch.tensor(1234.5678, dtype=torch.float64))


def test_variance_precise_on_bright_low_contrast_image():
    x = 1e6 + _image(1, 40, 40)
    s = ring_sums(x, 2, 3)
    img = x[0, 0].numpy()
    ref = ring_cells(img, 20, 20, 2, 3).var()
    np.testing.assert_allclose(s.var()[0, 0, 20, 20].item(), ref, rtol=1e-9)


def test_region_signed_sum():
    reg = Region((Rect.box(2),), (Rect.box(0),))
    x = torch.ones(1, 1, 7, 7)
    assert rect_sums(x, [reg])[0].count[0, 0, 3, 3].item() == 24


def test_empty_batch():
    x = torch.zeros(0, 1, 8, 8)
    s = ring_sums(x, 1, 1)
    assert s.s1.shape == (0, 1, 8, 8)


@pytest.mark.parametrize("masked", [False, True])
def test_mean_in_place_equals_mean(masked):
    x = _image(5, 12, 13, b=2)
    valid = (
        torch.rand(x.shape, generator=torch.Generator().manual_seed(1)) > 0.7 if masked else None
    )
    s = ring_sums(x, 1, 1, valid=valid)
    want = s.mean()
    assert masked == bool((s.count == 0).any())  # the masked case has empty rings
    assert torch.equal(s.mean_(), want)


@pytest.mark.skipif(not _jit.enabled(), reason="numba kernels not available")
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("masked", [False, True])
@pytest.mark.parametrize("moments", [1, 2])
@pytest.mark.parametrize("strip", [None, 5])
def test_compiled_strip_sums_equal_the_tensor_code_bit_for_bit(
    monkeypatch, dtype, masked, moments, strip
):
    g = torch.Generator().manual_seed(3)
    x = (torch.rand(3, 2, 23, 17, generator=g, dtype=torch.float64) * 1e3).to(dtype)
    valid = torch.rand(x.shape, generator=g) > 0.3 if masked else None
    shapes = [Ring(1, 2).region, *pinwheel_rects(1, 2), Rect(-4, -1, 0, 3), Rect.box(0)]

    def collect(_xs, sums):
        out = []
        for s in sums:
            out += [s.count.expand_as(s.s1), s.s1] + ([s.s2] if moments == 2 else [])
        return tuple(out)

    monkeypatch.setattr(windows, "_direct", lambda *_: False)  # integral images
    got = []
    for on in (True, False):
        monkeypatch.setattr(_jit, "ENABLED", on)
        got.append(windowed(x, shapes, collect, valid=valid, moments=moments, strip=strip))
    for a, b in zip(*got, strict=True):
        assert a.dtype == b.dtype == torch.float64 and torch.equal(a, b)


def test_strip_sums_of_a_tensor_needing_gradients_use_the_tensor_code():
    x = _image(2, 10, 10).requires_grad_()
    ring_sums(x, 1, 1).s1.sum().backward()
    assert x.grad is not None and torch.isfinite(x.grad).all()
