"""Milliseconds per megapixel and per image (chip) of each detector, as ``torchsar-eval run``
configures it.

Two image kinds: 128x128 simulated chips (a batch of 64) and 800x800 real images (the HRSID
samples, display values squared, when the sample data are present, else simulated scenes).
Each detector is timed on 1 thread, the median of ``--repeat`` runs after a warm-up; CPU
(thread) time is reported beside wall time because it is the fairer figure on a busy host.
``--python-path`` also times every detector with the compiled numba kernels switched off
(:mod:`torchsar._jit`; the numpy/torch code they replace, same results), interleaved with
the default run so both see the same load, and prints the ratio. Run the same script on
two checkouts to compare anything else.

Usage: ``python scripts/detector_speed.py [--detectors ca,os,...] [--repeat N]
[--python-path] [--csv PATH]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
import numpy as np
import torch
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from torchsar import _jit
from torchsar_eval.datasets import make_dataset
from torchsar_eval.registry import BUILTIN

HRSID = Path(__file__).resolve().parents[2] / "shared" / "data" / "hrsid"
DEFAULT = "ca,two_parameter,go,so,os,vi,ac,lognormal,weibull,gamma,k,g0,region"


def images(hrsid: Path) -> dict[str, torch.Tensor]:
    """The two test batches: chips and 800x800 images."""
    chips = make_dataset("sim-chips", n=64, seed=0)
    out = {"chips 128x128": torch.stack([chips[i]["image"] for i in range(len(chips))])}
    if hrsid.is_dir():  # read here, not by a dataset scheme, so any checkout reads the same
        files = sorted(f for f in hrsid.glob("*.png") if "_instance" not in f.name)
        amp = [np.asarray(Image.open(f).convert("L"), dtype=np.float32) / 255 for f in files]
        out["HRSID 800x800"] = torch.from_numpy(np.stack(amp)[:, None] ** 2)
    else:
        big = make_dataset("sim-scenes", n=4, seed=0)
        out["sim-scenes"] = torch.stack([big[i]["image"] for i in range(len(big))])
    return out


def _timed(fn, x: torch.Tensor) -> tuple[float, float]:
    t0, c0 = time.perf_counter(), time.thread_time()
    fn(x)
    return time.perf_counter() - t0, time.thread_time() - c0


def python_path(fn):
    """``fn`` with the compiled kernels switched off."""

    def run(x: torch.Tensor):
        old, _jit.ENABLED = _jit.ENABLED, False
        try:
            return fn(x)
        finally:
            _jit.ENABLED = old

    return run


def medians(fns: dict, x: torch.Tensor, repeat: int) -> dict[str, tuple[float, float]]:
    """Median wall and CPU seconds of each function of ``fns`` on ``x``: one warm-up each,
    then ``repeat`` interleaved rounds."""
    for fn in fns.values():
        fn(x)
    runs: dict[str, list[tuple[float, float]]] = {k: [] for k in fns}
    for _ in range(repeat):
        for k, fn in fns.items():
            runs[k].append(_timed(fn, x))
    return {
        k: (statistics.median(t[0] for t in v), statistics.median(t[1] for t in v))
        for k, v in runs.items()
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--detectors", default=DEFAULT)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--python-path", action="store_true", help="also time without numba")
    p.add_argument("--csv", type=Path)
    p.add_argument("--hrsid", type=Path, default=HRSID, help="folder of HRSID PNG samples")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    specs = [BUILTIN[n] for n in args.detectors.split(",")]
    rows = []
    for kind, x in images(args.hrsid).items():
        n_img, mp = x.shape[0], x[:, 0].numel() / 1e6
        for spec in specs:
            fns = {"compiled": spec}
            if args.python_path:
                fns["python"] = python_path(spec)
            got = medians(fns, x, args.repeat)
            for path, (wall, cpu) in got.items():
                rows.append(
                    (
                        kind,
                        spec.name,
                        path,
                        wall * 1e3 / mp,
                        cpu * 1e3 / mp,
                        wall * 1e3 / n_img,
                        cpu * 1e3 / n_img,
                    )
                )
                print(
                    f"{kind:24s} {spec.name:14s} {path:8s} {rows[-1][3]:8.1f} ms/MP "
                    f"(cpu {rows[-1][4]:8.1f})  {rows[-1][5]:8.2f} ms/image "
                    f"(cpu {rows[-1][6]:8.2f})",
                    flush=True,
                )
            if args.python_path:
                ratio = got["python"][1] / max(got["compiled"][1], 1e-12)
                print(f"{'':24s} {spec.name:14s} python / compiled cpu time: {ratio:.2f}x")
    if args.csv:
        import pandas as pd

        cols = [
            "images",
            "detector",
            "path",
            "ms_per_mp",
            "cpu_ms_per_mp",
            "ms_per_image",
            "cpu_ms_per_image",
        ]
        pd.DataFrame(rows, columns=cols).to_csv(args.csv, index=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
