"""The library and the evaluator on every available device, against the CPU.

On a machine without CUDA only ``cpu`` is tested (the test logic and API stay exercised:
every comparison is then CPU against CPU); where CUDA is present, ``cuda`` runs too and
these are the GPU checks: every window CFAR, every speckle filter, the region CFAR (tensor
parts on the device, its heap on the CPU), the imaging routines and a default evaluator run.

Tolerances: detection masks are compared exactly up to pixels whose statistic lies within
the statistic's tolerance of the threshold (float64 integral images summed in another order
on the GPU may flip such a near-tie); statistics agree to ``1e-5`` relative, except the K
and G0 CFARs (``2e-3``): their log-cumulant fit through the inverse trigamma amplifies an
ulp of the input (CPU and GPU logarithms differ by about that) up to ~10^3 times in
heavy-tailed rings, which :func:`test_tolerance_covers_one_ulp_of_input` measures on the
CPU alone; speckle filters to ``1e-4``; imaging to ``1e-3`` of the image peak (float32
FFTs in another order).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch

import torchsar as ts
import torchsar_eval as te

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
CFARS = [
    "ca",
    "two_parameter",
    "go",
    "so",
    "os",
    "vi",
    "ac",
    "lognormal",
    "weibull",
    "gamma",
    "k",
    "g0",
]


@pytest.fixture(scope="module")
def chips() -> torch.Tensor:
    """Two 64 x 64 speckled chips with targets (gamma clutter, seeded)."""
    return ts.simulate.chips(2, size=64, length_px=(8, 20), seed=3).image


RTOL = {"k": 2e-3, "g0": 2e-3}  # statistics' relative tolerance (default 1e-5), see above


def _same_detection(got, want, rtol: float = 1e-5) -> None:
    got_s, want_s = got.statistic.cpu().double(), want.statistic.double()
    finite = torch.isfinite(want_s)
    assert torch.equal(torch.isfinite(got_s), finite)
    assert torch.allclose(got_s[finite], want_s[finite], rtol=rtol, atol=1e-8)
    thr = want.threshold.double()
    near = ((want_s - thr).abs() <= rtol * thr.abs().clamp_min(1e-12)) & finite
    differ = got.mask.cpu() != want.mask
    assert not (differ & ~near).any(), f"{int((differ & ~near).sum())} mask pixels differ"


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("name", CFARS)
def test_window_cfars(name, device, chips):
    fn = getattr(ts.cfar, name)
    want = fn(chips)
    got = fn(chips.to(device))
    assert got.mask.device.type == device and got.statistic.device.type == device
    _same_detection(got, want, RTOL.get(name, 1e-5))


@pytest.mark.parametrize("device", DEVICES)
def test_os_is_exact_on_every_device(device, chips):
    """OS-CFAR's order statistic is exact everywhere (on CUDA: the Triton kernels' bisection
    over counts), so its statistic is the CPU's bit for bit, and ``os_mask`` (on CUDA: the
    counting decision alone) is its mask."""
    want = ts.cfar.os(chips)
    got = ts.cfar.os(chips.to(device))
    assert torch.equal(got.statistic.cpu(), want.statistic)
    assert torch.equal(got.mask.cpu(), want.mask)
    assert torch.equal(ts.cfar.os_mask(chips.to(device)).cpu(), want.mask)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA only")
def test_cuda_takes_the_triton_kernels(chips):
    """On CUDA, float32 CA and OS without no-data run as the fused Triton kernels (when
    Triton is installed, as it is with CUDA builds of torch)."""
    from torchsar import _triton

    if not _triton.ENABLED:
        pytest.skip("triton is not installed")
    assert _triton.for_tensor(chips.cuda())
    ca = ts.cfar.ca(chips.cuda(), guard=1, train=3)
    want = ts.cfar.ca(chips, guard=1, train=3)
    _same_detection(ca, want, 1.2e-7)  # a float32 ulp: every ring summed directly


@pytest.mark.parametrize("name", sorted(RTOL))
def test_tolerance_covers_one_ulp_of_input(name, chips):
    """The CPU against itself with every input value moved by about one float32 ulp
    (relative 1.2e-7, seeded): the K and G0 statistics stay within a tenth of their wider
    tolerance, so it is not hiding a device error larger than the detectors' own
    conditioning."""
    fn = getattr(ts.cfar, name)
    gen = torch.Generator().manual_seed(0)
    moved = chips * (1 + 1.2e-7 * torch.randn(chips.shape, generator=gen))
    a, b = fn(chips).statistic.double(), fn(moved).statistic.double()
    finite = torch.isfinite(a) & torch.isfinite(b)
    assert torch.allclose(b[finite], a[finite], rtol=RTOL[name] / 10, atol=1e-9)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("name", sorted(ts.speckle.FILTERS))
def test_speckle_filters(name, device, chips):
    fn = ts.speckle.FILTERS[name]
    want = fn(chips)
    got = fn(chips.to(device))
    assert got.device.type == device
    assert torch.allclose(got.cpu(), want, rtol=1e-4, atol=1e-6 * float(want.abs().max()))


@pytest.mark.parametrize("device", DEVICES)
def test_region_cfar(device, chips):
    want = ts.region.region_cfar(chips)
    got = ts.region.region_cfar(chips.to(device))
    assert got.statistic.device.type == device
    _same_detection(got, want)
    assert torch.equal(got.labels.cpu(), want.labels)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("name", ["ca", "os", "lee"])
def test_a_tiled_scene_on_the_device_is_the_cpu_run(name, device):
    """Tiles read ahead and (on CUDA) copied on their own stream from pinned memory: every
    tile's outputs as on the CPU (masks up to near-threshold ties)."""
    from torchsar.cfar.design import threshold
    from torchsar.tiling import iter_tiles

    scene = torch.empty(300, 280).exponential_(generator=torch.Generator().manual_seed(4))
    scene[100:104, 50:55] = 40.0
    x = scene.numpy()
    want = {t.index: out for t, out in iter_tiles(x, name, tile=64, batch=3)}
    got = {t.index: out for t, out in iter_tiles(x, name, tile=64, batch=3, device=device)}
    assert got.keys() == want.keys() and len(got) == 25
    for index, w in want.items():
        g = got[index]
        for k in w:
            if k != "mask":
                np.testing.assert_allclose(g[k], w[k], rtol=1e-5, atol=1e-8)
        if "mask" in w:
            thr = threshold(name)
            near = np.abs(w["statistic"].astype(np.float64) - thr) <= 1e-5 * thr
            assert not ((g["mask"] != w["mask"]) & ~near).any(), index
    if name != "lee":
        assert sum(int(w["mask"].sum()) for w in want.values()) > 0


def _close_images(got: torch.Tensor, want: torch.Tensor) -> None:
    peak = float(want.abs().max())
    assert got.device.type in DEVICES
    assert float((got.cpu() - want).abs().max()) <= 1e-3 * peak


@pytest.mark.parametrize("device", DEVICES)
def test_imaging(device):
    scene, _ = ts.imaging.point_scene(2, size=(32, 32), points=6, seed=1)
    g = ts.imaging.fft2c(scene[:, 0])  # (B, M, K) phase history
    g_err = ts.imaging.apply_phase_error(g, ts.imaging.quadratic_phase_error(2, 32, seed=2))
    on = g_err.to(device)
    _close_images(ts.imaging.lp_image(on, max_iter=5), ts.imaging.lp_image(g_err, max_iter=5))
    got = ts.imaging.sparse_autofocus(on, max_iter=5)
    want = ts.imaging.sparse_autofocus(g_err, max_iter=5)
    _close_images(got.image, want.image)
    _close_images(
        ts.imaging.pga(ts.imaging.ifft2c(on)[:, None]).image,
        ts.imaging.pga(ts.imaging.ifft2c(g_err)[:, None]).image,
    )


@pytest.mark.parametrize("device", DEVICES)
def test_a_default_run_gives_the_same_tables(device):
    dets = ["ca", "two_parameter", "go", "so", "os", "vi", "ac", "region"]
    if device == "cpu":  # CPU against CPU only checks that the option is honoured
        dets = ["ca", "region"]
    want = te.evaluate("sim-chips", dets, n=6, progress=False)
    got = te.evaluate("sim-chips", dets, n=6, progress=False, execution=te.Execution(device=device))
    for table in ("summary", "froc", "pr", "breakdown"):
        pd.testing.assert_frame_equal(
            getattr(got, table), getattr(want, table), check_exact=False, rtol=1e-6
        )
