"""The GPU report of ``scripts/benchmark.py``: its rows agree with themselves on a tiny dry
run (``device="cpu"``: the same code against itself), a failing detector is reported in
its row, and without a CUDA device and no ``--device`` it refuses in one line."""

from __future__ import annotations

import pytest
import torch

from tests.scripts import SCRIPTS, load_script


@pytest.fixture(scope="module")
def gpu():
    return load_script("benchmark").load_topic(SCRIPTS / "benchmarks" / "gpu.py")


def test_dry_run_rows_are_consistent(gpu):
    rows = gpu.report(
        n=3, device="cpu", cpu_images=2, repeat=1, size=48, detectors=("ca", "os", "os_mask", "g0")
    )
    names = [r["detector"] for r in rows]
    assert names == ["copy", "naive_ca", "ca", "os", "os_mask", "g0"]
    for r in rows[:2]:  # the baselines: device columns only
        assert r["error"] is None and r["device_ms"] > 0 and r["cpu_ms_per_mp"] is None
    for r in rows[2:]:
        assert r["error"] is None and r["images"] == 3 and r["cpu_images"] == 2
        mp = 48 * 48 / 1e6
        assert r["device_mp_per_s"] == pytest.approx(3 * mp / (r["device_ms"] / 1e3))
        assert r["device_ms_per_mp"] == pytest.approx(r["device_ms"] / (3 * mp))
        assert r["speedup"] == pytest.approx(r["cpu_ms_per_mp"] / r["device_ms_per_mp"])
        assert r["mask_pixels_differ"] == 0  # the same device: the same masks
    table = gpu.format_rows(rows)
    assert table.count("\n") == 6 and "MP/s" in table


def test_the_naive_baseline_is_ca_cfar_in_the_interior(gpu):
    """The five-line torch CA the targets are stated against detects as CA-CFAR does away
    from the border (float32 box sums: up to near-threshold ties)."""
    import torchsar as ts

    x = gpu.speckle(2, 64)
    x[0, 0, 30, 30] = 60.0
    naive = gpu.naive_ca(x)[..., 6:-6, 6:-6]
    ours = ts.cfar.ca(x)
    inner = ours.statistic[..., 6:-6, 6:-6]
    near = (inner - ours.threshold).abs() <= 1e-4 * ours.threshold
    assert not ((naive != ours.mask[..., 6:-6, 6:-6]) & ~near).any() and naive.any()


def test_a_failing_detector_is_reported_in_its_row(gpu, monkeypatch):
    import torchsar as ts

    ca = ts.cfar.ca

    def broken(x):
        if x.shape[0] > 1:  # the device batch; the CPU images run
            raise RuntimeError("CUDA out of memory. Tried to allocate 9 GiB")
        return ca(x)

    monkeypatch.setattr(ts.cfar, "ca", broken)
    (row,) = gpu.report(
        n=2, device="cpu", cpu_images=1, repeat=1, size=32, detectors=("ca",), baselines=False
    )
    assert row["error"].startswith("RuntimeError: CUDA out of memory")
    assert row["device_ms"] is None and row["cpu_ms_per_mp"] > 0
    assert "error: RuntimeError" in gpu.format_rows([row])


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the refusal without a GPU")
def test_refuses_without_a_gpu(gpu):
    with pytest.raises(SystemExit, match="needs a CUDA device"):
        gpu.report(n=1, size=16)
