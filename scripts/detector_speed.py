"""Milliseconds per megapixel of each detector, as ``torchsar-eval run`` configures it.

Two image kinds: 128x128 simulated chips (a batch of 64) and 800x800 real images (the HRSID
samples, display values squared, when the sample data are present, else simulated scenes).
Each detector is timed on 1 thread, best of ``--repeat`` runs after a warm-up; CPU time is
reported beside wall time because it is the fairer figure on a busy host. Run the same
script on two checkouts to get before/after figures.

Usage: ``python scripts/detector_speed.py [--detectors ca,os,...] [--repeat N] [--csv PATH]``
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
import numpy as np
import torch
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

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


def best(fn, x: torch.Tensor, repeat: int) -> tuple[float, float]:
    """Best wall and CPU seconds of ``repeat`` runs of ``fn(x)`` after one warm-up."""
    fn(x)
    wall, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn(x)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return min(wall), min(cpu)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--detectors", default=DEFAULT)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--csv", type=Path)
    p.add_argument("--hrsid", type=Path, default=HRSID, help="folder of HRSID PNG samples")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    specs = [BUILTIN[n] for n in args.detectors.split(",")]
    rows = []
    for kind, x in images(args.hrsid).items():
        mp = x[:, 0].numel() / 1e6
        for spec in specs:
            wall, cpu = best(spec, x, args.repeat)
            rows.append((kind, spec.name, wall * 1e3 / mp, cpu * 1e3 / mp))
            print(f"{kind:28s} {spec.name:14s} {rows[-1][2]:9.1f} ms/MP  (cpu {rows[-1][3]:9.1f})")
    if args.csv:
        import pandas as pd

        cols = ["images", "detector", "ms_per_mp", "cpu_ms_per_mp"]
        pd.DataFrame(rows, columns=cols).to_csv(args.csv, index=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
