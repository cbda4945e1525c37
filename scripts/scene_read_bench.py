"""Throughput of windowed scene reads on the big synthetic scene (write_scene_file).

Writes the 30,000 x 25,000 deflate BigTIFF (timed) and an uncompressed striped copy,
then reads the same seeded 1024 x 1024 windows, interleaved round by round, with:
TiffScene on the deflate file, TiffScene on the raw file (memmap path), a bare np.memmap
of the raw file, and tifffile.imread of the whole deflate file (one thread and default).
MB/s counts decoded uint16 bytes delivered. Files are freshly written, so reads come from
the page cache (warm). Prints one JSON object.

Usage: python scripts/scene_read_bench.py [--dir DIR] [--windows 24] [--rounds 2]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import tifffile

from torchsar.io import TiffScene
from torchsar.simulate.scene_file import write_scene_file


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--dir", default=None)
    ap.add_argument("--windows", type=int, default=24)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--skip-full", action="store_true", help="skip the whole-file imread")
    ap.add_argument("--reuse", action="store_true", help="reuse files already in --dir")
    args = ap.parse_args()
    folder = Path(args.dir or tempfile.mkdtemp(prefix="scene-bench-"))
    deflate, raw = folder / "scene.tif", folder / "scene-raw.tif"
    write_s = None
    if not (args.reuse and deflate.exists() and raw.exists()):
        t = time.perf_counter()
        write_scene_file(deflate)
        write_s = round(time.perf_counter() - t, 1)
        image = tifffile.imread(deflate, maxworkers=1)
        tifffile.imwrite(raw, image, rowsperstrip=64, bigtiff=True)
        del image
    with tifffile.TiffFile(raw) as tif:
        offset = int(tif.pages[0].dataoffsets[0])
    h, w, n = 30_000, 25_000, 1024
    rng = np.random.default_rng(0)
    boxes = [
        (int(rng.integers(0, h - n)), int(rng.integers(0, w - n))) for _ in range(args.windows)
    ]
    aligned = [(r // 512 * 512, c // 512 * 512) for r, c in boxes]
    # a tiling engine's pass: 1024 windows at stride 896 (128 overlap) over 8192 x 8192
    sliding = [(r, c) for r in range(9000, 17192 - n, 896) for c in range(4000, 12192 - n, 896)]
    mb = n * n * 2 / 1e6

    def ours(path: Path, where=boxes, cache_mb: float = 0) -> float:
        with TiffScene(path, cache_mb=cache_mb) as scene:
            t = time.perf_counter()
            for r, c in where:
                scene[r : r + n, c : c + n]
            return len(where) * mb / (time.perf_counter() - t)

    def bare_memmap() -> float:
        m = np.memmap(raw, np.uint16, "r", offset=offset, shape=(h, w))
        t = time.perf_counter()
        for r, c in boxes:
            np.array(m[r : r + n, c : c + n])
        return len(boxes) * mb / (time.perf_counter() - t)

    def whole(workers: int | None) -> float:
        t = time.perf_counter()
        tifffile.imread(deflate, maxworkers=workers)
        return h * w * 2 / 1e6 / (time.perf_counter() - t)

    results: dict[str, list[float]] = {}
    for _ in range(args.rounds):
        runs = {
            "tiffscene_deflate": lambda: ours(deflate),
            "tiffscene_deflate_tile_aligned": lambda: ours(deflate, aligned),
            "tiffscene_deflate_sliding_nocache": lambda: ours(deflate, sliding),
            "tiffscene_deflate_sliding_cache64": lambda: ours(deflate, sliding, 64),
            "tiffscene_raw_memmap": lambda: ours(raw),
            "np_memmap_raw": bare_memmap,
        }
        if not args.skip_full:
            runs["imread_whole_deflate_1thread"] = lambda: whole(1)
            runs["imread_whole_deflate_default"] = lambda: whole(None)
        for name, fn in runs.items():
            results.setdefault(name, []).append(fn())
    med = {k: float(np.median(v)) for k, v in results.items()}
    base = med["tiffscene_deflate"]
    print(
        json.dumps(
            {
                "write_s": write_s,
                "file_mb": round(os.path.getsize(deflate) / 1e6, 1),
                "mb_per_s": {k: round(v, 1) for k, v in med.items()},
                "ratio_to_tiffscene_deflate": {k: round(v / base, 2) for k, v in med.items()},
                "windows": len(boxes),
                "rounds": args.rounds,
                "cpu_count": os.cpu_count(),
                "loadavg": os.getloadavg(),
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
