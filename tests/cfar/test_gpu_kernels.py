"""The Triton kernels of CA-CFAR and OS-CFAR against slow references and the CPU code.

On a machine with CUDA they run on the GPU; without one, in Triton's interpreter on CPU
tensors (the same kernel code, executed step by step with numpy): the default test run
checks them there.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from functools import partial
from pathlib import Path

import numpy as np
import pytest
import torch

import torchsar as ts
from tests.reference.cfar import ca_reference, os_reference, zero_blocks_scene
from tests.reference.windows import exact_sums, first_cells
from torchsar import _jit, _triton
from torchsar.cfar.os_cfar import _factor, _gpu_tables
from torchsar.cfar.thresholds import ca_factor
from torchsar.windows import Ring

pytestmark = [
    pytest.mark.skipif(not _triton.enabled(), reason="triton not installed"),
    # the interpreter evaluates masked-off lanes too (x / 0 where no pixel is)
    pytest.mark.filterwarnings("ignore::RuntimeWarning:triton.*"),
]

DEVICE = "cuda" if torch.cuda.is_available() else "cpu"


def _kernels():
    return _triton.kernels()


def _scene(seed: int, shape=(2, 2, 29, 70)) -> torch.Tensor:
    """Exponential clutter with a bright target, a clutter edge and a dark patch (float32)."""
    g = torch.Generator().manual_seed(seed)
    x = torch.empty(shape, dtype=torch.float64).exponential_(generator=g)
    x[0, 0, 3:6, 4:8] *= 300.0
    x[-1, -1, :, shape[-1] // 2 :] *= 9.0
    if shape[-2] >= 27 and shape[-1] >= 40:
        x[0, -1, 5:26, 10:40] = 0.0  # whole rings of zeros: x / 0 = inf, 0 / 0 = 0
        x[0, -1, 15, 25] = 5.0
    return x.float()


def _ties(seed: int, shape=(1, 2, 19, 23)) -> torch.Tensor:
    """Small integers, zeros included: many equal ring values and exact ratio ties."""
    g = torch.Generator().manual_seed(seed)
    return torch.randint(0, 5, shape, generator=g).float()


def _ulps(got: np.ndarray, want: np.ndarray) -> float:
    """Largest difference in float32 ulps of ``want`` (non-finite entries must be equal)."""
    fin = np.isfinite(want)
    assert np.array_equal(got[~fin], want[~fin])
    spacing = np.spacing(np.abs(want[fin]).astype(np.float32)).astype(np.float64)
    return float((np.abs(got[fin] - want[fin]) / spacing).max(initial=0.0))


def _ca(x: torch.Tensor, guard: int, train: int, pfa: float = 1e-3):
    ring = Ring(guard, train)
    thr = torch.tensor(ca_factor(ring.n, pfa), dtype=torch.float32)
    from torchsar.cfar.core import geometric_scale

    scale = geometric_scale(*x.shape[-2:], ring, partial(ca_factor, pfa=pfa))
    stat, mask = _kernels().ring_ratio(x.to(DEVICE), guard, train, scale, thr.to(DEVICE))
    return stat.cpu(), mask.cpu(), thr


@pytest.mark.parametrize("guard, train", [(1, 2), (0, 1), (2, 3), (0, 4)])
def test_ca_kernel_is_the_exactly_summed_statistic(guard, train):
    """At every pixel, borders, zero rings and 0 / 0 included: within a float32 ulp of the
    statistic summed exactly (``math.fsum``), and the mask is the statistic over the
    threshold, exactly."""
    x = _scene(1, shape=(1, 2, 27, 42))
    stat, mask, thr = _ca(x, guard, train)
    want = ca_reference(x.double().numpy(), guard, train, 1e-3)
    assert np.isinf(want).any() and (want == 0).any()
    assert _ulps(stat.double().numpy(), want) <= 1.0
    assert torch.equal(mask, stat > thr) and mask.any()


# (1, 1, 40, 150): tiles of 16 x 64 whose windows lie inside (the unmasked loads) beside
# border tiles
@pytest.mark.parametrize("shape", [(1, 1, 11, 11), (1, 1, 40, 150), (1, 2, 40, 9)])
def test_ca_kernel_is_the_cpu_kernel_to_an_ulp(shape):
    """Images as small as the window, wider and taller than a tile, and narrow: the CPU's
    statistic to a float32 ulp; masks equal but at pixels that close to the threshold."""
    g = torch.Generator().manual_seed(sum(shape))
    x = torch.empty(shape).exponential_(generator=g)
    x[..., shape[-2] // 2, shape[-1] // 2] = 40.0
    guard, train = (2, 3) if min(shape[-2:]) >= 11 else (1, 2)
    stat, mask, thr = _ca(x, guard, train)
    cpu = ts.cfar.ca(x, guard=guard, train=train)
    assert _ulps(stat.double().numpy(), cpu.statistic.double().numpy()) <= 1.0
    near = (cpu.statistic.double() - float(thr)).abs() <= 2 * np.spacing(np.float32(thr))
    assert not ((mask != cpu.mask) & ~near).any()


def test_ca_kernel_keeps_its_precision_beside_a_very_bright_target():
    """Clutter of 1 beside a cell of 1e12: every ring without it is exactly 1 / 1."""
    x = torch.ones(1, 1, 48, 48)
    x[0, 0, 5, 5] = 1e12
    stat = _ca(x, 1, 2)[0]
    far = stat[0, 0, 12:-4, 12:-4]
    assert torch.equal(far, torch.ones_like(far))


def test_ca_kernel_does_not_depend_on_the_batch():
    x = _scene(2, shape=(3, 2, 27, 42))
    whole = _ca(x, 2, 3)[0]
    one_by_one = torch.cat([_ca(x[i : i + 1], 2, 3)[0] for i in range(x.shape[0])])
    assert torch.equal(whole, one_by_one)


def _os(x: torch.Tensor, guard: int, train: int, rank: int, pfa: float = 1e-3):
    ring = Ring(guard, train)
    factor = partial(_factor, n_full=ring.n, rank=rank, pfa=pfa)
    thr = torch.tensor(factor(ring.n), dtype=torch.float32)
    tables = _gpu_tables(x, ring, rank, factor)
    return factor, thr, tables


@pytest.mark.parametrize(
    "guard, train, rank",
    [(1, 2, None), (1, 2, 1), (1, 2, 40), (0, 3, 20), (2, 1, 7), (2, 4, None)],  # N = 144
)
@pytest.mark.parametrize("make", [_scene, _ties])
def test_os_kernels_are_the_sorted_reference(guard, train, rank, make):
    """The statistic bit for bit as sorting each ring gives it (border ranks and factors
    included); the mask by counting alone is exactly the statistic over the threshold."""
    x = make(3, shape=(1, 2, 27, 42))
    ring = Ring(guard, train)
    r = rank or max(1, round(3 * ring.n / 4))
    factor, thr, tables = _os(x, guard, train, r)
    xd = x.to(DEVICE)
    stat, mask = _kernels().os_ratio(xd, *tables, thr.to(DEVICE))
    decision = _kernels().os_decision(xd, *tables, thr.to(DEVICE))
    want = os_reference(x.numpy(), guard, train, r, factor)
    assert np.array_equal(stat.cpu().numpy(), want)
    assert torch.equal(mask.cpu(), torch.from_numpy(want) > thr)
    assert torch.equal(decision.cpu(), mask.cpu())


@pytest.mark.parametrize("thr", [0.0, 0.5, 1.0, 2.0, 1.5, 3.0, float("inf"), -1.0])
def test_os_decision_at_exact_ties(thr):
    """Integer images and thresholds that many statistics equal exactly (``>`` is strict),
    zero order statistics (``inf``) and zero cells (``0 / 0 = 0``), an infinite and a
    negative threshold: the count decides as the statistic does, pixel for pixel."""
    x = _ties(4, shape=(2, 1, 16, 21))
    guard, train, r = 1, 1, 4
    factor, _, tables = _os(x, guard, train, r)
    t = torch.tensor(thr, dtype=torch.float32)
    stat, _ = _kernels().os_ratio(x.to(DEVICE), *tables, t.to(DEVICE))
    decision = _kernels().os_decision(x.to(DEVICE), *tables, t.to(DEVICE))
    want = torch.from_numpy(os_reference(x.numpy(), guard, train, r, factor))
    assert torch.equal(stat.cpu(), want)
    assert torch.equal(decision.cpu(), want > t)
    if 0 < thr < 4:
        assert bool((want == t).any())  # the ties are there


def test_os_kernels_with_a_border_scale():
    """A frame of border factors far from 1 (a strict pfa): still exact."""
    x = _scene(5, shape=(1, 1, 20, 20))
    factor, thr, tables = _os(x, 2, 2, 20, pfa=1e-6)
    stat, mask = _kernels().os_ratio(x.to(DEVICE), *tables, thr.to(DEVICE))
    want = os_reference(x.numpy(), 2, 2, 20, factor)
    assert (tables[3] != 1).sum() > 5
    assert np.array_equal(stat.cpu().numpy(), want)
    assert torch.equal(
        _kernels().os_decision(x.to(DEVICE), *tables, thr.to(DEVICE)).cpu(), mask.cpu()
    )


def test_empty_batches():
    x = torch.empty(0, 1, 16, 16)
    stat, mask, _ = _ca(x, 1, 2)
    assert stat.shape == mask.shape == x.shape
    _, thr, tables = _os(x, 1, 2, 10)
    assert _kernels().os_decision(x.to(DEVICE), *tables, thr.to(DEVICE)).shape == x.shape


@pytest.fixture
def through_triton(monkeypatch):
    """The public detectors routed to the Triton kernels on this machine's device (the
    interpreter on CPU tensors without a GPU); the kernels' calls are counted."""
    calls = []
    kernels = _kernels()
    for name in ("ring_ratio", "os_ratio", "os_decision"):
        fn = getattr(kernels, name)

        def spy(*args, _fn=fn, _name=name, **kwargs):
            calls.append(_name)
            return _fn(*args, **kwargs)

        monkeypatch.setattr(kernels, name, spy)
    monkeypatch.setattr(
        _triton, "for_tensor", lambda t: t.dtype == torch.float32 and not t.requires_grad
    )
    return calls


def test_the_public_detectors_take_the_kernels(through_triton, monkeypatch):
    """``ca``, ``os``, ``os_mask`` and AC's ring mean go through the kernels on a float32
    image without no-data, and give the CPU code's results (OS bit for bit, CA to an ulp);
    with a ``valid`` mask or float64 CA and OS take the tensor code."""
    x = _scene(6, shape=(1, 2, 27, 42))
    with_kernels = {
        "ca": ts.cfar.ca(x.to(DEVICE), guard=1, train=3),
        "os": ts.cfar.os(x.to(DEVICE), guard=1, train=3),
        "ac": ts.cfar.ac(x.to(DEVICE), guard=1, train=3),
    }
    mask = ts.cfar.os_mask(x.to(DEVICE), guard=1, train=3)
    assert sorted(set(through_triton)) == ["os_decision", "os_ratio", "ring_ratio"]
    monkeypatch.setattr(_triton, "for_tensor", lambda t: False)
    for name, got in with_kernels.items():
        # AC on the GPU is the tensor code over the kernel's direct window sums, as its
        # CPU kernel sums the censored ring directly (inf where the kept cells are all
        # zero, where integral images leave a residue): the CPU kernel compares
        want = getattr(ts.cfar, name)(x, guard=1, train=3)
        assert got.threshold.dtype == want.threshold.dtype and torch.equal(
            got.threshold.cpu(), want.threshold
        )
        if name == "os":
            assert torch.equal(got.statistic.cpu(), want.statistic)
            assert torch.equal(got.mask.cpu(), want.mask)
        else:
            assert _ulps(got.statistic.cpu().double().numpy(), want.statistic.double().numpy()) <= 1
    assert torch.equal(mask.cpu(), with_kernels["os"].mask.cpu())


def test_no_data_and_float64_take_the_tensor_code(through_triton):
    x = _scene(7, shape=(1, 1, 12, 14))  # small: the window sums still take the kernel
    valid = torch.ones_like(x, dtype=torch.bool)
    valid[..., :3, :] = False
    ts.cfar.ca(x.to(DEVICE), guard=1, train=1, valid=valid.to(DEVICE))
    ts.cfar.os_mask(x.to(DEVICE), guard=1, train=1, valid=valid.to(DEVICE))
    ts.cfar.os(x.double().to(DEVICE), guard=1, train=1)
    assert through_triton == []


def test_the_kernels_are_used_on_cuda_float32_only(monkeypatch):
    cpu = torch.ones(1, 1, 8, 8)
    assert not _triton.for_tensor(cpu)
    monkeypatch.setattr(_triton, "works_on", lambda device: True)
    fake = torch.empty(1, 1, 8, 8, device="meta")  # device checks aside: what else decides
    monkeypatch.setattr(torch.Tensor, "device", property(lambda t: torch.device("cuda")))
    assert _triton.for_tensor(fake)
    assert not _triton.for_tensor(fake.double())
    assert not _triton.for_tensor(fake.requires_grad_())
    huge = torch.empty(1, 1, 1 << 16, 1 << 15, device="meta")  # 2^31 pixels in a plane
    assert not _triton.for_tensor(huge)
    monkeypatch.undo()
    monkeypatch.setattr(_triton, "ENABLED", False)
    assert _triton.kernels() is None and not _triton.enabled()


def test_the_kernels_compile_for_a_hopper_gpu(tmp_path):
    """Triton compiles every kernel variant to sm_90 machine code (H100, H200) on this
    machine, GPU or not (its compiler and bundled ptxas; no driver): what the interpreter
    cannot check (types, constructs the compiler refuses, register spills) is checked
    here."""
    repo = Path(__file__).resolve().parents[2]
    env = {k: v for k, v in os.environ.items() if k != "TRITON_INTERPRET"}
    env |= {"TRITON_CACHE_DIR": str(tmp_path), "PYTHONPATH": str(repo)}
    run = subprocess.run(
        [sys.executable, str(Path(__file__).with_name("compile_gpu_kernels.py"))],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    if "ptxas" in run.stderr and "not found" in run.stderr.lower():
        pytest.skip("this triton ships no ptxas")
    assert run.returncode == 0, run.stderr[-2000:]
    lines = run.stdout.splitlines()
    assert len(lines) == 9 and all(" ok " in line for line in lines), run.stdout
    # compiled as launched: no fused multiply-adds (IEEE operations as written), and where
    # ptxas reports them, at most a few bytes spilled (the float64 division's call frame)
    assert all(" fma=0 " in line for line in lines), run.stdout
    spills = [int(v) for v in re.findall(r"spills=(\d+)", run.stdout)]
    assert all(v <= 32 for v in spills), run.stdout


@pytest.mark.parametrize(
    "shape, r, rr",
    [
        ((2, 1, 23, 31), 0, 23),
        ((2, 1, 23, 31), 5, 7),
        ((2, 1, 23, 31), 20, 3),
        ((1, 1, 40, 140), 0, 40),  # interior tiles (unmasked loads) beside border ones
    ],
)
@pytest.mark.parametrize("masked", [False, True])
def test_region_sums_are_the_exactly_summed_windows(shape, r, rr, masked):
    """A ring, a box and a pinwheel block, for a strip of rows: every cell (every valid
    cell, with a mask, also counted) added directly in float64 as its deviation from the
    pixel's shift (the first in-image, valid cell of its regions), so within a few float64
    ulps of the sums of the window (relative to the sum of absolute deviations)."""
    from torchsar.windows import Rect, Region, disjoint_rects, pinwheel_rects

    x = _scene(8, shape=shape)
    h, w = shape[-2:]
    valid = None
    if masked:
        valid = torch.rand(shape, generator=torch.Generator().manual_seed(8)) > 0.3
        valid[..., 5:14, 3:12] = False  # windows without a valid cell
    regions = [Ring(1, 2).region, Region((Rect.box(2),)), Region((pinwheel_rects(1, 2)[1],))]
    parts = [disjoint_rects(reg) for reg in regions]
    on = None if valid is None else valid.to(DEVICE)
    s1, s2, shift, count = _kernels().region_sums(x.to(DEVICE), parts, r, rr, 2, on)
    assert s1.shape == s2.shape == (3, shape[0], 1, rr, w)
    assert (count is None) == (valid is None)
    flat = x.reshape(-1, h, w).double().numpy()
    ok = None if valid is None else valid.reshape(-1, h, w).numpy()
    first = first_cells(flat, parts, ok)
    assert np.array_equal(shift.cpu().reshape(-1, rr, w).numpy(), first[:, r : r + rr])
    for q, rects in enumerate(parts):
        want1, want2, n = exact_sums(flat, rects, first, ok)
        got1 = s1[q].cpu().reshape(-1, rr, w).numpy()
        got2 = s2[q].cpu().reshape(-1, rr, w).numpy()
        scale = np.abs(want1[:, r : r + rr]).max() + want2[:, r : r + rr].max()
        np.testing.assert_allclose(got1, want1[:, r : r + rr], rtol=0, atol=1e-13 * scale)
        np.testing.assert_allclose(got2, want2[:, r : r + rr], rtol=1e-13, atol=1e-13 * scale)
        if count is not None:
            assert np.array_equal(count[q].cpu().reshape(-1, rr, w).numpy(), n[:, r : r + rr])


@pytest.mark.parametrize("guard, train", [(0, 1), (2, 4), (1, 3)])
def test_disjoint_rects_cover_the_ring_once(guard, train):
    from torchsar.windows import Rect, Region, disjoint_rects

    ring = Ring(guard, train)
    cells = [
        (a, b)
        for r0, r1, c0, c1 in disjoint_rects(ring.region)
        for a in range(r0, r1 + 1)
        for b in range(c0, c1 + 1)
    ]
    assert len(cells) == len(set(cells)) == ring.n
    assert set(cells) == {tuple(o) for o in ring.offsets().tolist()}
    assert disjoint_rects(Region((Rect.box(2),))) == [(-2, 2, -2, 2)]
    two = Region((Rect.box(1), Rect(3, 4, 0, 0)))
    outside = Region((Rect.box(1),), (Rect(1, 2, 0, 0),))
    assert disjoint_rects(two) is None and disjoint_rects(outside) is None


WINDOW_CFARS = ["ca", "two_parameter", "go", "so", "vi", "lognormal", "weibull", "gamma", "k"]


@pytest.fixture
def sums_through_triton(monkeypatch):
    """Every window sum through the Triton kernel (the numba kernels off, so the speckle
    filters and CFARs take the tensor code's windows, as on a GPU)."""
    from torchsar import _jit

    monkeypatch.setattr(_jit, "ENABLED", False)
    calls = []
    kernels = _kernels()
    fn = kernels.region_sums

    def spy(*args, **kwargs):
        calls.append(1)
        return fn(*args, **kwargs)

    monkeypatch.setattr(kernels, "region_sums", spy)
    monkeypatch.setattr(
        _triton, "for_tensor", lambda t: t.dtype == torch.float32 and not t.requires_grad
    )
    return calls


def test_window_statistics_through_the_kernel(sums_through_triton, monkeypatch):
    """The window CFARs and speckle filters on the kernel's sums: the CPU's results to the
    device tests' tolerances (statistics 1e-5 relative, K 2e-3; masks up to near-ties;
    speckle filters 1e-4)."""
    x = _scene(9, shape=(1, 2, 24, 30))
    got = {n: getattr(ts.cfar, n)(x.to(DEVICE)) for n in WINDOW_CFARS}
    filtered = {n: f(x.to(DEVICE)) for n, f in ts.speckle.FILTERS.items()}
    assert len(sums_through_triton) >= len(WINDOW_CFARS) + len(filtered) - 2  # Frost: shells
    monkeypatch.setattr(_triton, "for_tensor", lambda t: False)
    for name, d in got.items():
        want = getattr(ts.cfar, name)(x)
        rtol = 2e-3 if name == "k" else 1e-5
        ws, gs = want.statistic.double(), d.statistic.cpu().double()
        fin = torch.isfinite(ws)
        assert torch.equal(torch.isfinite(gs), fin), name
        assert torch.allclose(gs[fin], ws[fin], rtol=rtol, atol=1e-8), name
        near = (ws - want.threshold.double()).abs() <= rtol * want.threshold.double().abs()
        assert not ((d.mask.cpu() != want.mask) & ~near).any(), name
    for name, out in filtered.items():
        want = ts.speckle.FILTERS[name](x)
        assert torch.allclose(out.cpu(), want, rtol=1e-4, atol=1e-6 * float(want.max())), name


def test_window_statistics_with_no_data_through_the_kernel(sums_through_triton, monkeypatch):
    """With a no-data mask the window CFARs take the kernel's sums of the valid cells and
    their counts; the CPU adds the same cells in the same order
    (:func:`torchsar._windows_kernels.direct_sums`), so its statistics and masks are the
    same bit for bit where it takes them (VI); the others take their one-sweep kernels on
    the CPU (other sums of the same cells: within a float32 ulp, masks up to near-ties;
    invalid pixels -inf on both)."""
    x = _scene(10, shape=(1, 1, 20, 24))  # small: the interpreter runs every cell
    valid = torch.rand(x.shape, generator=torch.Generator().manual_seed(10)) > 0.2
    valid[0, 0, 4:12, 5:14] = False
    got = {n: getattr(ts.cfar, n)(x.to(DEVICE), valid=valid.to(DEVICE)) for n in WINDOW_CFARS}
    assert len(sums_through_triton) >= len(WINDOW_CFARS)
    monkeypatch.setattr(_triton, "for_tensor", lambda t: False)
    monkeypatch.setattr(_jit, "ENABLED", True)
    for name, d in got.items():
        want = getattr(ts.cfar, name)(x, valid=valid)
        if DEVICE == "cpu" and name == "vi":  # the same sums, the same operations
            assert torch.equal(d.statistic, want.statistic), name
            assert torch.equal(d.mask, want.mask), name
            continue
        rtol = 2e-3 if name == "k" else 1e-5  # a GPU's special functions differ in ulps
        ws, gs = want.statistic.double(), d.statistic.cpu().double()
        fin = torch.isfinite(ws)
        assert torch.equal(torch.isfinite(gs), fin), name
        assert torch.equal(gs[~fin], ws[~fin]), name
        assert torch.allclose(gs[fin], ws[fin], rtol=rtol, atol=1e-8), name
        near = (ws - want.threshold.double()).abs() <= rtol * want.threshold.double().abs()
        assert not ((d.mask.cpu() != want.mask) & ~near).any(), name


def test_rect_sums_through_the_kernel_keep_their_shifts(sums_through_triton, monkeypatch):
    """``rect_sums`` on the kernel's sums returns their per-pixel shifts with them, so its
    means and variances are the CPU's (with and without a mask)."""
    from torchsar.windows import Rect, rect_sums

    x = _scene(11, shape=(1, 1, 14, 18))
    valid = torch.rand(x.shape, generator=torch.Generator().manual_seed(11)) > 0.2
    rects = [Ring(1, 2).region, Rect.box(1)]
    for mask in (None, valid):
        got = rect_sums(x.to(DEVICE), rects, valid=None if mask is None else mask.to(DEVICE))
        assert sums_through_triton
        with monkeypatch.context() as m:
            m.setattr(_triton, "for_tensor", lambda t: False)
            want = rect_sums(x, rects, valid=mask)
        for a, b in zip(got, want, strict=True):
            assert torch.allclose(a.mean().cpu(), b.mean(), rtol=1e-12, atol=1e-12)
            assert torch.allclose(a.var().cpu(), b.var(), rtol=1e-9, atol=1e-9)


def test_negative_zero_is_zero_on_every_path(monkeypatch):
    """``-0.0`` passes the input checks; a ring of ``-0.0`` around a bright cell is a ring of
    zeros on every path (compiled CPU kernels, tensor code, Triton kernels): ``+inf``, the
    same statistic and mask, not ``-inf`` from dividing by a signed zero."""
    from torchsar import _jit

    x = torch.ones(1, 1, 12, 12)
    x[..., 2:10, 2:10] = -0.0
    x[..., 6, 6] = 5.0
    opts = {"guard": 1, "train": 1}
    runs = {}
    for name, numba, gpu in [
        ("numba", True, False),
        ("tensor", False, False),
        ("triton", True, True),
    ]:
        monkeypatch.setattr(_jit, "ENABLED", numba)
        monkeypatch.setattr(
            _triton, "for_tensor", lambda t, on=gpu: on and t.dtype == torch.float32
        )
        xd = x.to(DEVICE) if gpu else x
        runs[name] = {
            "ca": ts.cfar.ca(xd, **opts),
            "os": ts.cfar.os(xd, rank=4, **opts),
            "os_mask": ts.cfar.os_mask(xd, rank=4, **opts),
        }
    for name, run in runs.items():
        for det in ("ca", "os"):
            stat = run[det].statistic.cpu()
            assert stat[0, 0, 6, 6] == float("inf"), (name, det)
            assert torch.equal(stat, runs["numba"][det].statistic), (name, det)
            assert torch.equal(run[det].mask.cpu(), runs["numba"][det].mask), (name, det)
        assert torch.equal(run["os_mask"].cpu(), runs["numba"]["os"].mask), name


def test_strips_of_any_height_give_the_same_values(sums_through_triton, monkeypatch):
    """Where the kernel sums the windows, the strips are sized by the batch (few launches);
    each window is summed on its own, so any strip height gives the same statistic."""
    from torchsar import windows

    x = _scene(10, shape=(2, 1, 40, 33))
    whole = ts.cfar.vi(x.to(DEVICE)).statistic.cpu()
    assert windows._gpu_strip_rows(x) == 40
    monkeypatch.setattr(windows, "_GPU_STRIP_ELEMENTS", 7 * 33)  # strips of 16 rows
    assert windows._gpu_strip_rows(x) == 16
    assert torch.equal(ts.cfar.vi(x.to(DEVICE)).statistic.cpu(), whole)


def test_a_device_the_kernels_fail_on_falls_back_with_one_warning(monkeypatch):
    """The first use on a device runs the kernels on a tiny image: where they cannot run
    (no C compiler for Triton's launcher, an unsupported driver), one warning and the tensor
    code from there on."""
    monkeypatch.setattr(_triton, "_WORKS", {})
    assert _triton.works_on(DEVICE)

    def broken(*args, **kwargs):
        raise RuntimeError("Failed to find C compiler. Please specify via CC environment")

    monkeypatch.setattr(_triton, "_WORKS", {})
    monkeypatch.setattr(_kernels(), "ring_ratio", broken)
    with pytest.warns(UserWarning, match="do not run on .*Failed to find C compiler"):
        assert not _triton.works_on(DEVICE)
    assert not _triton.works_on(DEVICE)  # remembered: no second warning


def test_a_pixel_without_ring_cells_is_never_detected():
    """Called directly (the detectors refuse images smaller than the ring first): the
    centre of a 3 x 3 image has no ring cell inside it for guard 1 (rank 0), and neither the
    decision nor the statistic's mask detects it."""
    x = torch.ones(1, 1, 3, 3)
    _, _, tables = _os(x, 1, 2, 10)
    assert tables[2][0] == 0
    t = torch.tensor(0.5).to(DEVICE)
    assert not _kernels().os_decision(x.to(DEVICE), *tables, t)[0, 0, 1, 1]
    stat, mask = _kernels().os_ratio(x.to(DEVICE), *tables, t)
    assert stat[0, 0, 1, 1] == float("-inf") and not mask[0, 0, 1, 1]


@pytest.mark.parametrize("seed", [1, 5, 10])  # each missed detections before
def test_zero_blocks_beside_bright_targets_through_the_kernel(
    sums_through_triton, monkeypatch, seed
):
    """Blocks of exact zeros and targets up to 1e12 times the clutter: the window sums as
    deviations from a cell of each pixel's own window give the CPU's detections (before,
    as deviations from the image's mean, the two-parameter CFAR disagreed with the CPU on
    up to 88 pixels beside such blocks, VI on up to 4: their variance did not cancel)."""
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(24, 32, 2))
    img = zero_blocks_scene(rng, h, w)
    x = torch.from_numpy(img).float()
    g, t = int(rng.integers(0, 3)), int(rng.integers(1, 4))
    names = ["two_parameter", "vi", "so", "go"]
    got = {n: getattr(ts.cfar, n)(x.to(DEVICE), guard=g, train=t) for n in names}
    assert sums_through_triton
    monkeypatch.setattr(_triton, "for_tensor", lambda t: False)
    monkeypatch.setattr(_jit, "ENABLED", True)  # the CPU's direct sums
    for name, d in got.items():
        assert torch.equal(d.mask.cpu(), getattr(ts.cfar, name)(x, guard=g, train=t).mask), name
