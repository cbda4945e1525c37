"""Benchmark report: the twelve window CFARs on a GPU against the same code on 1 CPU thread.

A seeded batch of ``n`` (default 64) speckle images of 1024x1024 (unit-mean exponential
intensity, float32) is run through every window CFAR with its default options on the
device, and its first ``cpu_images`` (default 2) images on the CPU with 1 thread. GPU time
is the median of ``repeat`` runs after a warm-up, each closed by a device synchronise; CPU
time likewise. Each row gives megapixels per second on the device, milliseconds per
megapixel on both, their ratio (CPU time over device time per megapixel: how many times
faster the device is), and the number of mask pixels that differ between the device's and
the CPU's results on the images both ran (near-ties of float64 sums summed in another
order; the device tests bound them). A detector that fails on the device (out of memory,
say) gets its error in the ``error`` column instead of stopping the report.

Beside them, the baselines the issue's targets are stated against, measured in the same
run on the same batch: ``copy`` (a device-to-device copy of the batch: the memory limit)
and ``naive_ca`` (CA-CFAR as two float32 ``avg_pool2d`` box sums, ring = big - small, one
compare: what a PyTorch user writes in five lines), and ``os_mask`` (OS-CFAR's mask alone:
on a GPU the counting decision, no order statistic). Baseline rows have no CPU columns.

Run: ``python scripts/benchmark.py --topic gpu [--n 64] [--device cuda]`` (needs a CUDA
device; ``--device cpu`` runs the same code on the CPU against itself, a dry run).
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import torch

CFARS = (
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
)
BASELINES = ("copy", "naive_ca")
DEFAULT_N = 64
SIZE = 1024
COLUMNS = (
    "detector",
    "device",
    "images",
    "device_ms",
    "device_mp_per_s",
    "device_ms_per_mp",
    "cpu_images",
    "cpu_ms_per_mp",
    "speedup",
    "mask_pixels_differ",
    "error",
)


def _median_seconds(fn: Callable[[], object], sync: Callable[[], None], repeat: int) -> float:
    fn()
    sync()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        sync()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _device(device: str | None) -> torch.device:
    if device is None:
        if not torch.cuda.is_available():
            raise SystemExit("the gpu topic needs a CUDA device (or --device cpu for a dry run)")
        device = "cuda"
    return torch.device(device)


def speckle(n: int, size: int = SIZE, seed: int = 0) -> torch.Tensor:
    """``(n, 1, size, size)`` float32 unit-mean exponential intensity, seeded, on the CPU."""
    gen = torch.Generator().manual_seed(seed)
    return torch.empty(n, 1, size, size).exponential_(generator=gen)


def _on_device(fn, xd: torch.Tensor, cpu_images: int, sync, repeat: int):
    """Median seconds of ``fn`` on the device batch ``xd`` and its mask on the first
    ``cpu_images`` images (on the CPU)."""
    seconds = _median_seconds(lambda: fn(xd), sync, repeat)
    return seconds, fn(xd[:cpu_images]).mask.cpu()


class _Mask:
    """A mask-only result, read as a detection's ``mask`` is."""

    def __init__(self, mask: torch.Tensor) -> None:
        self.mask = mask


def _detector(name: str) -> Callable[[torch.Tensor], object]:
    import torchsar as ts

    if name == "os_mask":
        return lambda x: _Mask(ts.cfar.os_mask(x))
    return lambda x: getattr(ts.cfar, name)(x)  # looked up per call: tests replace them


def naive_ca(x: torch.Tensor, guard: int = 2, train: int = 4, pfa: float = 1e-3) -> torch.Tensor:
    """CA-CFAR as a PyTorch user writes it: float32 box means by ``avg_pool2d`` (zero
    padding), ring mean from the outer and guard boxes, ``I > alpha * mean``."""
    from torchsar.cfar.thresholds import ca_factor

    pool = torch.nn.functional.avg_pool2d

    o, g = guard + train, guard
    big, small = (2 * o + 1) ** 2, (2 * g + 1) ** 2
    outer = pool(x, 2 * o + 1, stride=1, padding=o) * big
    inner = pool(x, 2 * g + 1, stride=1, padding=g) * small
    alpha = ca_factor(big - small, pfa)
    return x > alpha * (outer - inner) / (big - small)


def measure_baseline(name: str, xd: torch.Tensor, dev: torch.device, repeat: int) -> dict:
    """One row of :data:`COLUMNS` for a baseline (``copy`` or ``naive_ca``) on the device
    batch ``xd``."""
    fn = (lambda x: x.clone()) if name == "copy" else naive_ca
    sync = torch.cuda.synchronize if dev.type == "cuda" else (lambda: None)
    mp = xd[0, 0].numel() / 1e6
    row = dict.fromkeys(COLUMNS)
    row.update(detector=name, device=str(dev), images=xd.shape[0])
    try:
        seconds = _median_seconds(lambda: fn(xd), sync, repeat)
    except (RuntimeError, MemoryError) as err:
        row["error"] = f"{type(err).__name__}: {str(err).splitlines()[0][:160]}"
        return row
    row["device_ms"] = seconds * 1e3
    row["device_mp_per_s"] = xd.shape[0] * mp / seconds
    row["device_ms_per_mp"] = seconds * 1e3 / (xd.shape[0] * mp)
    return row


def measure(name: str, x: torch.Tensor, dev: torch.device, cpu_images: int, repeat: int) -> dict:
    """One row of :data:`COLUMNS` for the CFAR ``name`` (or ``os_mask``) on the batch ``x``
    (on the CPU)."""
    fn = _detector(name)
    mp = x[0, 0].numel() / 1e6
    row = dict.fromkeys(COLUMNS)
    row.update(detector=name, device=str(dev), images=x.shape[0], cpu_images=cpu_images)
    xc = x[:cpu_images].clone()
    cpu_s = _median_seconds(lambda: fn(xc), lambda: None, repeat)
    row["cpu_ms_per_mp"] = cpu_s * 1e3 / (cpu_images * mp)
    sync = torch.cuda.synchronize if dev.type == "cuda" else (lambda: None)
    try:
        dev_s, got = _on_device(fn, x.to(dev), cpu_images, sync, repeat)
    except (RuntimeError, MemoryError) as err:  # out of memory, a missing kernel: reported
        row["error"] = f"{type(err).__name__}: {str(err).splitlines()[0][:160]}"
        return row
    finally:
        if dev.type == "cuda":
            torch.cuda.empty_cache()
    row["device_ms"] = dev_s * 1e3
    row["device_mp_per_s"] = x.shape[0] * mp / dev_s
    row["device_ms_per_mp"] = dev_s * 1e3 / (x.shape[0] * mp)
    row["speedup"] = row["cpu_ms_per_mp"] / row["device_ms_per_mp"]
    row["mask_pixels_differ"] = int((got != fn(xc).mask).sum())
    return row


def report(
    n: int = DEFAULT_N,
    device: str | None = None,
    workers: tuple[int, ...] = (),
    cpu_images: int = 2,
    repeat: int = 3,
    size: int = SIZE,
    detectors: tuple[str, ...] = (*CFARS, "os_mask"),
    baselines: bool = True,
) -> list[dict]:
    """Rows of :data:`COLUMNS`: the baselines (unless ``baselines`` is false), then one per
    detector (``workers`` is not used: one process)."""
    dev = _device(device)
    torch.set_num_threads(1)
    x = speckle(n, size)
    rows = []
    if baselines:
        xd = x.to(dev)
        rows += [measure_baseline(name, xd, dev, repeat) for name in BASELINES]
        del xd
    return rows + [measure(name, x, dev, min(cpu_images, n), repeat) for name in detectors]


def format_rows(rows: list[dict]) -> str:
    """The rows as an aligned text table."""
    lines = [
        f"{'detector':<14s} {'device':<7s} {'images':>6s} {'device ms':>10s} "
        f"{'MP/s':>9s} {'dev ms/MP':>10s} {'cpu ms/MP':>10s} {'speedup':>8s} "
        f"{'differ':>7s}"
    ]
    for r in rows:
        head = f"{r['detector']:<14s} {r['device']:<7s} {r['images']:6d} "
        if r["cpu_ms_per_mp"] is None and not r["error"]:  # a baseline: the device only
            lines.append(
                head + f"{r['device_ms']:10.2f} {r['device_mp_per_s']:9.1f} "
                f"{r['device_ms_per_mp']:10.4f}"
            )
            continue
        if r["error"]:
            lines.append(
                head + f"{'':>10s} {'':>9s} {'':>10s} {r['cpu_ms_per_mp'] or 0:10.3f}   "
                f"error: {r['error']}"
            )
            continue
        lines.append(
            head + f"{r['device_ms']:10.2f} {r['device_mp_per_s']:9.1f} "
            f"{r['device_ms_per_mp']:10.4f} {r['cpu_ms_per_mp']:10.3f} "
            f"{r['speedup']:8.1f} {r['mask_pixels_differ']:7d}"
        )
    return "\n".join(lines)
