"""The compiled per-pixel rules of GO, SO and VI over windowed sums (with no-data), of CA
over a masked ring (CA with no-data, AC) and OS-CFAR's ratio and border factors give the
tensor code's statistic and mask bit for bit over the same window sums: clutter edges, flat zero images, bright
targets, no-data masks that empty whole halves, both float dtypes."""

from __future__ import annotations

import importlib

import pytest
import torch

import torchsar.cfar as cfar
from tests.kernel_paths import rules_both
from torchsar import _jit

pytestmark = pytest.mark.skipif(not _jit.enabled(), reason="numba kernels not available")


def _scene(seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    x = torch.empty(5, 2, 41, 38).exponential_(generator=g)
    x[0, 0, 10:14, 10:14] *= 80.0  # a target
    x[1, 1, :, 20:] *= 9.0  # a clutter edge
    x[2] = 0.0  # nothing at all: 0 / 0 everywhere
    x[3, 0, ::3, :] *= 30.0  # striped, variable halves
    return x


ONE_SWEEP = {("ca", False), ("go", False), ("so", False), ("vi", False), ("ac", False)}
ONE_SWEEP |= {("ca", True), ("ac", True), ("go", True), ("so", True)}  # with no-data too
"""Their one-sweep kernels sum the windows directly (within an ulp of the tensor code):
tests/test_box_kernels.py, tests/test_pinwheel_kernels.py."""

RULE_MODULES = [
    importlib.import_module(f"torchsar.cfar.{m}") for m in ("blocks", "vi", "ca", "ac", "os_cfar")
]
"""The modules of the rules: switched off there, the same window sums take the tensor code."""

RULES = [
    (name, masked)
    for name in ("go", "so", "vi", "ca", "ac", "os")
    for masked in (False, True)
    if (name, masked) not in ONE_SWEEP
]


@pytest.mark.parametrize("name, masked", RULES)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_compiled_rules_equal_the_tensor_code(monkeypatch, name, dtype, masked):
    x = _scene(1).to(dtype)
    valid = None
    if masked:
        valid = torch.rand(x.shape, generator=torch.Generator().manual_seed(2)) > 0.3
        valid[4, :, :, :19] = False  # whole halves and blocks without a counted cell
    detector = getattr(cfar, name)
    call = lambda: detector(x, guard=1, train=3, valid=valid)  # noqa: E731
    a, b = rules_both(monkeypatch, call, RULE_MODULES)
    assert a.statistic.dtype == b.statistic.dtype
    assert torch.equal(a.statistic, b.statistic) and torch.equal(a.mask, b.mask)


@pytest.mark.parametrize("name", ["vi"])
def test_compiled_rules_over_integral_images(monkeypatch, name):
    """Windows of more cells than the CPU sums one by one take the integral images (one
    shift per image, broadcast for the compiled rule): the tensor code's statistic bit for
    bit there too."""
    from torchsar.windows import DIRECT_CELLS, Ring

    assert 2 * Ring(1, 9).n > DIRECT_CELLS
    x = _scene(4)[:1, :1]
    valid = torch.rand(x.shape, generator=torch.Generator().manual_seed(4)) > 0.3
    detector = getattr(cfar, name)
    call = lambda: detector(x, guard=1, train=9, valid=valid)  # noqa: E731
    a, b = rules_both(monkeypatch, call, RULE_MODULES)
    assert torch.equal(a.statistic, b.statistic) and torch.equal(a.mask, b.mask)


@pytest.mark.parametrize("name", ["go", "vi"])
def test_compiled_rules_do_not_depend_on_the_batch(name):
    x = _scene(3)
    detector = getattr(cfar, name)
    whole = detector(x).statistic
    for i in range(x.shape[0]):
        assert torch.equal(detector(x[i : i + 1]).statistic, whole[i : i + 1])


def test_stacked_planes_are_a_view_when_adjacent_else_a_copy():
    from torchsar.cfar.core import stack_planes

    base = torch.rand(5, 2, 1, 4, 6, dtype=torch.float64)
    view = stack_planes([base[i] for i in range(4)])
    assert view.data_ptr() == base.data_ptr() and torch.equal(view, base[:4])
    copy = stack_planes([base[0], base[2]])
    assert copy.data_ptr() != base.data_ptr() and torch.equal(copy, base[[0, 2]])
    geometric = stack_planes([torch.ones(4, 6), base[1]])  # an (rr, W) count broadcast
    assert geometric.shape == (2, 2, 1, 4, 6) and torch.equal(geometric[1], base[1])


@pytest.mark.parametrize("name", ["go", "so", "vi"])
def test_remembered_border_factors_change_nothing(monkeypatch, name):
    import importlib

    modules = [importlib.import_module(f"torchsar.cfar.{m}") for m in ("blocks", "vi")]
    detector = getattr(cfar, name)
    x = _scene(5)
    first, again = detector(x).statistic, detector(x[:2]).statistic  # the second reuses them
    for module in modules:
        monkeypatch.setattr(module, "geometric_cached", lambda key, counts, make, **_: make())
    assert torch.equal(detector(x).statistic, first)
    assert torch.equal(detector(x[:2]).statistic, again)


def test_only_counts_shared_by_the_batch_are_remembered():
    from torchsar.cfar.core import geometric_cached

    calls = []

    def make():
        calls.append(1)
        return torch.zeros(1)

    def cached(counts, geometric=True):
        return geometric_cached(("t",), counts, make, geometric=geometric)

    shared = torch.ones(4, 6)
    cached([shared]), cached([shared.clone()])
    assert len(calls) == 1
    cached([shared + 1])  # other counts: evaluated again
    per_image = torch.ones(2, 1, 4, 6)
    cached([per_image]), cached([per_image])
    assert len(calls) == 4
    one_image = torch.ones(1, 1, 4, 6)  # one image's counts of a no-data mask
    cached([one_image], geometric=False), cached([one_image], geometric=False)
    assert len(calls) == 6


@pytest.mark.parametrize("name", ["go", "so", "vi"])
def test_the_counts_of_a_mask_are_not_remembered(name):
    """A single image's no-data counts look like the geometry's (unit batch and channel
    dims) but are the mask's: hashed and kept as keys they cost more than the factors (and
    up to 16 copies of 4 full-size planes in memory)."""
    from torchsar.cfar import core

    x = _scene(6)[:1, :1]
    valid = torch.rand(x.shape, generator=torch.Generator().manual_seed(6)) > 0.1
    before = dict(core._GEOMETRIC)
    for _ in range(2):
        getattr(cfar, name)(x, valid=valid)
    assert dict(core._GEOMETRIC).keys() == before.keys()


@pytest.mark.parametrize("name", ["go", "so", "vi"])
def test_factors_remembered_from_other_masks_change_nothing(name):
    """With no-data the border factors are looked up in tables filled as block sizes are
    met (each factor evaluated once per process): a mask met after others gives the
    statistic it gives with empty tables, bit for bit."""
    import importlib

    blocks, vi = (importlib.import_module(f"torchsar.cfar.{m}") for m in ("blocks", "vi"))
    x = _scene(7)[:1, :1].double()
    gen = torch.Generator().manual_seed(7)
    masks = [torch.rand(x.shape, generator=gen) > p for p in (0.05, 0.3, 0.6)]
    detector = getattr(cfar, name)
    fresh = []
    for m in masks:
        blocks._size_factors.cache_clear()
        vi._half_tables.cache_clear()
        fresh.append(detector(x, valid=m).statistic)
    for m in reversed(masks):
        detector(x, valid=m)  # tables holding every mask's sizes
    for m, want in zip(masks, fresh, strict=True):
        assert torch.equal(detector(x, valid=m).statistic, want)


@pytest.mark.parametrize("name", ["go", "so"])
def test_no_data_factors_of_a_wide_window_are_kept_by_the_sizes_met(monkeypatch, name):
    """GO / SO with no-data and a wide window (blocks of 620 cells: billions of possible
    size tuples, a table over them would need tens of GB): the factors of the sizes met,
    the tensor code's statistic to float64 rounding (its window sums come from integral
    images here, the kernel's cell by cell) and its mask."""
    x = torch.empty(1, 1, 56, 60, dtype=torch.float64).exponential_(
        generator=torch.Generator().manual_seed(8)
    )
    valid = torch.rand(x.shape, generator=torch.Generator().manual_seed(9)) > 0.05
    detector = getattr(cfar, name)
    call = lambda: detector(x, guard=5, train=20, valid=valid)  # noqa: E731
    a, b = rules_both(monkeypatch, call, RULE_MODULES)
    torch.testing.assert_close(a.statistic, b.statistic, rtol=1e-14, atol=0)
    assert torch.equal(a.mask, b.mask)
