"""A whole scene from host memory through a tiled window CFAR on a device, beside the time
of copying the scene's bytes to that device (the transfer bound).

    python scripts/scene_device.py --size 16384 --device cuda --tile 2048 --detectors ca os

The scene is seeded unit-mean exponential clutter (float32, in host memory). Each detector
runs over it with :func:`torchsar.tiling.iter_tiles` (the next tiles read on a second
thread while these run) after a warm-up on one tile; the figure is megapixels per second
of the whole pass, outputs back in host memory. The copy is one ``Tensor.to(device)`` of
the scene (pageable memory), synchronised.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from torchsar.tiling import iter_tiles


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=16384)
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--tile", type=int, default=2048)
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--detectors", nargs="+", default=["ca", "os"])
    args = ap.parse_args(argv)
    dev = torch.device(args.device)
    gen = np.random.default_rng(0)
    scene = gen.standard_exponential((args.size, args.size), dtype=np.float32)
    mpx = scene.size / 1e6
    t0 = time.perf_counter()
    on = torch.from_numpy(scene).to(dev)
    _sync(dev)
    copy = time.perf_counter() - t0
    del on
    print(f"scene {args.size}^2 ({mpx:.0f} Mpx): host -> {dev} copy {copy:.3f} s")
    for name in args.detectors:
        warm = scene[: args.tile, : args.tile]
        for _ in iter_tiles(warm, name, tile=args.tile, device=dev):
            pass
        _sync(dev)
        t0 = time.perf_counter()
        found = 0
        for _tile, out in iter_tiles(scene, name, tile=args.tile, batch=args.batch, device=dev):
            found += int(out["mask"].sum())
        _sync(dev)
        sec = time.perf_counter() - t0
        print(
            f"{name}: {sec:.3f} s, {mpx / sec:,.0f} Mpx/s "
            f"({sec / copy:.1f}x the copy), {found} detections"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
