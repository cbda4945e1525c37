"""Tiled vs untiled: throughput (Mpx/s) and peak RSS of a detector on one scene, each run
in a fresh process on 1 thread, tiled and untiled interleaved.

    .venv/bin/python scripts/tiling_speed.py --sizes 4096 8192 --detectors ca os region

Scenes are seeded exponential clutter with planted targets (``tests/tiling/_rss.py``),
written once as float32 ``.npy`` memmaps in ``--dir``. Tiled runs use
:func:`torchsar.tiling.run_scene` with default tiles and memmap outputs; untiled runs load
the scene as one tensor and call the detector on it. ``--skip-untiled`` lists
``detector:size`` pairs not to run untiled (their memory would not fit the machine).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _child(path: str, detector: str, mode: str, outdir: str) -> None:
    import torch

    import torchsar as ts

    torch.set_num_threads(1)
    scene = np.load(path, mmap_mode="r")
    if detector == "region":  # compile outside the timing (cached on disk afterwards)
        ts.region.region_cfar(torch.from_numpy(np.array(scene[:64, :64]))[None, None])
    t0 = time.perf_counter()
    if mode == "tiled":
        out = {
            "mask": np.lib.format.open_memmap(f"{outdir}/m.npy", "w+", bool, scene.shape),
            "statistic": np.lib.format.open_memmap(
                f"{outdir}/s.npy", "w+", np.float32, scene.shape
            ),
        }
        ts.tiling.run_scene(scene, detector, out=out)
    else:
        x = torch.from_numpy(np.array(scene))[None, None]
        fn = ts.region.region_cfar if detector == "region" else getattr(ts.cfar, detector)
        fn(x)
    wall = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    print(json.dumps({"seconds": wall, "peak": peak}))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="+", default=[4096, 8192])
    ap.add_argument("--detectors", nargs="+", default=["ca", "os", "region"])
    ap.add_argument("--dir", default="/tmp/tiling_speed")
    ap.add_argument("--skip-untiled", nargs="*", default=[])
    a = ap.parse_args()
    Path(a.dir).mkdir(parents=True, exist_ok=True)
    print("detector size mode Mpx/s peak_GB")
    for size in a.sizes:
        path = Path(a.dir) / f"scene{size}.npy"
        if not path.exists():
            subprocess.run(
                [sys.executable, "-m", "tests.tiling._rss", "write", str(path), str(size)],
                cwd=ROOT,
                check=True,
            )
        for det in a.detectors:
            for mode in ("untiled", "tiled"):
                if mode == "untiled" and f"{det}:{size}" in a.skip_untiled:
                    print(det, size, mode, "skipped", flush=True)
                    continue
                r = subprocess.run(
                    [sys.executable, __file__, "--child", str(path), det, mode, a.dir],
                    cwd=ROOT,
                    capture_output=True,
                    text=True,
                    check=True,
                )
                res = json.loads(r.stdout.strip().splitlines()[-1])
                mpx = size * size / 1e6 / res["seconds"]
                print(det, size, mode, f"{mpx:.2f}", f"{res['peak'] / 2**30:.2f}", flush=True)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        _child(*sys.argv[2:6])
    else:
        main()
