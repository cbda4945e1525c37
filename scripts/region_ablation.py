"""Failure modes of the literal region-growing CFAR and what each fix contributes.

Runs the region CFAR on a simulated dataset with the paper's preset, then adds the fixes of
the ``torchsar`` preset one at a time (flood limit, object size floor, ``k``, ``tau``, hole
filling), and prints object Pd, false alarms per image, fragmentation, mean IoU, FoM, the
number of accepted regions larger than 20000 px (accepted floods) and ms per image.

Usage: ``PYTHONPATH=. python scripts/region_ablation.py [--dataset sim-scenes] [--n 6]``;
``--dataset bench-scenes`` uses the benchmark's 512x512 scenes (1-look speckle, a 6 dB
clutter edge, 30-120 px targets, tight pairs; ``scripts/benchmarks/region.py``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

import torchsar as ts
from torchsar_eval.batches import batches
from torchsar_eval.datasets import make_dataset
from torchsar_eval.detector import Detector
from torchsar_eval.runner import run_detectors
from torchsar_eval.tables import markdown, summary_table

sys.path.insert(0, str(Path(__file__).resolve().parent / "benchmarks"))
from region import scene  # the benchmark's scene generator


class BenchScenes(torch.utils.data.Dataset):
    """The benchmark scenes as an evaluator dataset."""

    def __init__(self, n: int, seed: int) -> None:
        self.n, self.seed = n, seed

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, i: int) -> dict:
        x, inst = scene(512, 12, self.seed + i)
        return {
            "image": x[0],
            "mask": inst[0] > 0,
            "instances": inst[0],
            "ignore": torch.zeros_like(inst[0], dtype=torch.bool),
            "meta": {"name": f"bench/{i}"},
        }


STEPS = [
    ("paper", {}),
    ("+ max_size 20000", {"max_size": 20_000}),
    ("+ min_size 30", {"min_size": 30}),
    ("+ k 2", {"k": 2.0}),
    ("+ tau 0.5", {"tau": 0.5}),
    ("+ fill_holes (= torchsar)", {"fill_holes": True, "merge": 0}),
]


def specs() -> list[Detector]:
    out, acc = [], {"preset": "paper"}
    for name, extra in STEPS:
        acc = {**acc, **extra}
        out.append(Detector(name, ts.region.region_cfar, dict(acc)))
    return out


def floods(ds, spec: Detector, batch_size: int) -> int:
    """Accepted regions larger than 20000 px (larger than any target) over the dataset."""
    params = {k: v for k, v in spec.params.items() if k != "preset"}
    n = 0
    for b in batches(ds, batch_size):
        r = ts.region.region_search(b["image"], preset="paper", **params)
        n += sum(int(np.sum((t.column("size") > 20_000) & t.column("accepted"))) for t in r.tables)
    return n


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dataset", default="sim-scenes")
    p.add_argument("--n", type=int, default=6)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    torch.set_num_threads(1)
    if args.dataset == "bench-scenes":
        ds = BenchScenes(args.n, args.seed)
    else:
        ds = make_dataset(args.dataset, n=args.n, seed=args.seed)
    sp = specs()
    table = summary_table({args.dataset: run_detectors(ds, sp, batch_size=4, progress=False)})
    table["accepted_floods"] = [floods(ds, s, 4) for s in sp]
    cols = [
        "detector",
        "pd_object",
        "false_alarms_per_image",
        "fragmentation",
        "mean_iou",
        "fom",
        "accepted_floods",
        "ms_per_image",
    ]
    print(markdown(table[cols], floatfmt=".3g"))


if __name__ == "__main__":
    main()
