"""The CPU's direct window sums (:func:`torchsar._windows_kernels.direct_sums`): every cell
added on its own in float64, as deviations from the pixel's first in-image (valid) cell, in
the Triton kernel's order, so the CPU's window statistics are a GPU's bit for bit and lose
nothing beside bright targets or blocks of zeros (integral images cancel there)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import torchsar as ts
from tests.reference.cfar import zero_blocks_scene
from tests.reference.windows import exact_sums, first_cells, ordered_sums
from torchsar import _jit, _triton, windows
from torchsar.windows import Rect, Region, Ring, disjoint_rects, pinwheel_rects, rect_sums

pytestmark = pytest.mark.skipif(not _jit.enabled(), reason="numba kernels not available")

REGIONS = [Ring(1, 2).region, Region((Rect.box(2),)), Region((pinwheel_rects(1, 2)[1],))]


def _kernel(x: np.ndarray, parts, r: int, rr: int, moments: int, valid: np.ndarray | None):
    from torchsar import _windows_kernels

    rects = np.array([t for region in parts for t in region], np.int64)
    starts = np.cumsum([0] + [len(region) for region in parts]).astype(np.int64)
    flags = np.zeros((1, 1, 1), np.uint8) if valid is None else valid.astype(np.uint8)
    return _windows_kernels.direct_sums(x, flags, valid is not None, rects, starts, r, rr, moments)


def _scene(seed: int, shape) -> np.ndarray:
    """Exponential clutter with a target 1e6 times brighter and a block of exact zeros."""
    rng = np.random.default_rng(seed)
    x = rng.exponential(size=shape)
    x[0, 2:4, 3:5] *= 1e6
    x[-1, -6:, -7:] = 0.0
    return x


def _assert_in_order(x, parts, r, rr, moments, valid, got) -> None:
    """The kernel's results ``got`` for output rows ``r .. r + rr - 1`` are the cells added
    in order (:func:`ordered_sums`) from the first in-image (valid) cell, bit for bit."""
    s1, s2, shift, count = got
    flat = x.astype(np.float64)
    first = first_cells(flat, parts, valid)
    assert np.array_equal(shift, first[:, r : r + rr])
    for q, rects in enumerate(parts):
        want1, want2, n = ordered_sums(flat, rects, first, valid)
        assert np.array_equal(s1[q], want1[:, r : r + rr])
        if moments == 2:
            assert np.array_equal(s2[q], want2[:, r : r + rr])
        if valid is not None:
            assert np.array_equal(count[q], n[:, r : r + rr])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("masked", [False, True])
@pytest.mark.parametrize("moments", [1, 2])
@pytest.mark.parametrize(
    "shape, r, rr", [((2, 13, 17), 0, 13), ((1, 13, 17), 4, 5), ((1, 3, 4), 0, 3)]
)
def test_direct_sums_are_the_cells_added_in_order(dtype, masked, moments, shape, r, rr):
    """Bit for bit the cells added one after the other in the kernel's order (rectangle by
    rectangle, row by row), as deviations from the first in-image (valid) cell in that
    order, counted where valid: strips of rows, windows wider than the image, both input
    dtypes, one or two moments."""
    x = _scene(1, shape).astype(dtype)
    valid = None
    if masked:
        valid = np.random.default_rng(2).random(shape) > 0.3
        valid[:, 1:3, :] = False  # windows without a valid cell
    parts = [disjoint_rects(reg) for reg in REGIONS]
    got = _kernel(x, parts, r, rr, moments, valid)
    assert got[1].shape[0] == (3 if moments == 2 else 0)
    assert got[3].shape[0] == (3 if masked else 0)
    _assert_in_order(x, parts, r, rr, moments, valid, got)


def test_direct_sums_are_within_float64_ulps_of_the_exact_sums():
    """Beside a target 1e6 times the clutter and a block of zeros, every window's sums are
    within a few float64 ulps of its exact sums (no cancellation: a window of zeros sums
    to 0 exactly, whatever lies elsewhere)."""
    x = _scene(3, (1, 15, 19))
    parts = [disjoint_rects(Ring(1, 2).region)]
    s1, s2, shift, _ = _kernel(x, parts, 0, 15, 2, None)
    want1, want2, _ = exact_sums(x, parts[0], first_cells(x, parts))
    cells, _, n = exact_sums(x, parts[0], np.zeros_like(x))  # x >= 0: the sums of |x|
    assert np.all(np.abs(s1[0] - want1) <= 1e-14 * (cells + n * shift))
    np.testing.assert_allclose(s2[0], want2, rtol=1e-14, atol=0)
    zeros = (shift == 0.0) & (want2 == 0.0)
    assert zeros.any() and np.all(s1[0][zeros] == 0.0) and np.all(s2[0][zeros] == 0.0)


@pytest.mark.skipif(not _triton.enabled(), reason="triton not installed")
@pytest.mark.filterwarnings("ignore::RuntimeWarning:triton.*")
@pytest.mark.parametrize("masked", [False, True])
def test_direct_sums_are_the_triton_kernels_bit_for_bit(masked):
    """The same values as the GPU's kernel (:func:`torchsar._gpu_kernels.region_sums`, here
    in Triton's interpreter), shifts and counts included."""
    shape = (1, 2, 14, 20)
    x = torch.from_numpy(_scene(4, (2, 14, 20))).float().reshape(shape)
    valid = None
    if masked:
        valid = torch.rand(shape, generator=torch.Generator().manual_seed(4)) > 0.25
    parts = [disjoint_rects(reg) for reg in REGIONS]
    device = "cuda" if torch.cuda.is_available() else "cpu"
    on = None if valid is None else valid.to(device)
    gpu = _triton.kernels().region_sums(x.to(device), parts, 2, 9, 2, on)
    cpu = windows._cpu_direct_sums(x, parts, 2, 9, 2, valid)
    for a, b in zip(gpu, cpu, strict=True):
        assert (a is None) == (b is None)
        if a is not None:
            assert torch.equal(a.cpu(), b)


def test_windowed_sums_on_the_cpu_are_direct():
    """With the kernels on, a CPU tensor's rectangle and ring sums are the direct sums (a
    plane of per-pixel shifts) up to ``DIRECT_CELLS`` cells in all; larger windows,
    regions of other shapes, and the kernels off, take the integral images (one shift per
    image)."""
    x = torch.from_numpy(_scene(5, (1, 40, 40))).float().reshape(1, 1, 40, 40)
    assert rect_sums(x, [Ring(1, 1).region])[0].shift.shape == (1, 1, 40, 40)
    side = int(windows.DIRECT_CELLS**0.5)  # a box of at most DIRECT_CELLS cells
    assert rect_sums(x, [Rect.box(side // 2)])[0].shift.shape == (1, 1, 40, 40)
    cells = windows.DIRECT_CELLS // 2
    half, rest = Rect(0, 0, 0, cells - 1), Rect(1, 1, 0, windows.DIRECT_CELLS - cells - 1)
    assert half.area + rest.area == windows.DIRECT_CELLS  # two regions: as many cells
    assert rect_sums(x, [half, rest])[0].shift.shape == (1, 1, 40, 40)
    more = Rect(1, 1, 0, windows.DIRECT_CELLS - cells)  # one cell too many
    assert rect_sums(x, [half, more])[0].shift.shape == (1, 1, 1, 1)
    other = Region((Rect.box(1),), (Rect(0, 0, 3, 3),))  # a box minus a cell outside it
    assert rect_sums(x, [other])[0].shift.shape == (1, 1, 1, 1)
    with pytest.MonkeyPatch.context() as m:
        m.setattr(_jit, "ENABLED", False)
        assert rect_sums(x, [Ring(1, 1).region])[0].shift.shape == (1, 1, 1, 1)


@pytest.mark.parametrize("seed", range(6))
def test_no_data_detections_beside_zero_blocks_are_the_direct_sums(seed):
    """Blocks of exact zeros, targets up to 1e12 times the clutter and a no-data mask: the
    window CFARs' statistics on the CPU are those of the windows summed exactly (before,
    VI's integral images of deviations from the plane's mean changed detections in about
    a quarter of such images)."""
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(22, 28, 2))
    x = torch.from_numpy(zero_blocks_scene(rng, h, w)).float()
    valid = torch.from_numpy(rng.random(x.shape) > 0.15)
    g, t = int(rng.integers(0, 3)), int(rng.integers(1, 3))
    got = ts.cfar.vi(x, guard=g, train=t, valid=valid)
    # the four blocks' means and variances from exact sums (the blocks make the ring)
    flat = x.reshape(1, h, w).double().numpy()
    ok = valid.reshape(1, h, w).numpy()
    parts = [[(r.r0, r.r1, r.c0, r.c1)] for r in pinwheel_rects(g, t)]
    first = first_cells(flat, parts, ok)
    exact = [exact_sums(flat, rects, first, ok) for rects in parts]
    s1 = torch.from_numpy(np.stack([e[0] for e in exact]))
    s2 = torch.from_numpy(np.stack([e[1] for e in exact]))
    n = torch.from_numpy(np.stack([e[2] for e in exact]))
    sums = [
        windows.Sums(
            n[q].view(1, 1, h, w),
            s1[q].view(1, 1, h, w),
            s2[q].view(1, 1, h, w),
            torch.from_numpy(first).view(1, 1, h, w),
        )
        for q in range(4)
    ]
    with pytest.MonkeyPatch.context() as m:
        m.setattr(windows, "_direct_strip_sums", lambda *a, **k: sums)
        want = ts.cfar.vi(x, guard=g, train=t, valid=valid)
    assert torch.equal(got.mask, want.mask)


@st.composite
def _cases(draw):
    """A small plane stack, a strip of its rows, one to three regions of one to three
    disjoint rectangles (row bands at distinct offsets), a mask or none."""
    p, h, w = draw(st.integers(1, 2)), draw(st.integers(1, 9)), draw(st.integers(1, 11))
    r = draw(st.integers(0, h - 1))
    rr = draw(st.integers(1, h - r))
    regions, row = [], -6
    for _ in range(draw(st.integers(1, 3))):
        rects = []
        for _ in range(draw(st.integers(1, 3))):
            top = row
            row += draw(st.integers(1, 2))
            c0 = draw(st.integers(-6, 5))
            rects.append((top, row - 1, c0, c0 + draw(st.integers(0, 6))))
        regions.append(rects)
    seed = draw(st.integers(0, 2**16))
    return (p, h, w), r, rr, regions, draw(st.booleans()), draw(st.sampled_from([1, 2])), seed


@settings(max_examples=60, deadline=None)
@given(_cases())
def test_direct_sums_on_random_windows(case):
    """Any rectangles (beside, inside and beyond the image), strips and masks: the cells
    added in order, bit for bit, on clutter with exact zeros and a bright target."""
    shape, r, rr, parts, masked, moments, seed = case
    rng = np.random.default_rng(seed)
    x = rng.exponential(size=shape).astype(np.float32)
    x[rng.random(shape) < 0.2] = 0.0
    x.flat[int(rng.integers(x.size))] *= 1e6
    valid = rng.random(shape) > 0.3 if masked else None
    _assert_in_order(x, parts, r, rr, moments, valid, _kernel(x, parts, r, rr, moments, valid))
