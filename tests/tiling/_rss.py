"""Peak memory of a tiled run, measured in a fresh process (used by test_memory.py).

``python -m tests.tiling._rss write PATH SIZE``: write a seeded ``SIZE x SIZE`` float32
scene (exponential clutter and planted targets) as a ``.npy`` memmap, block by block.
``python -m tests.tiling._rss run PATH DETECTOR TILE``: run :func:`scene_objects` on the
memmap and print ``peak_rss_bytes objects``.
"""

from __future__ import annotations

import resource
import sys

import numpy as np


def write(path: str, size: int) -> None:
    mm = np.lib.format.open_memmap(path, "w+", np.float32, (size, size))
    block = 1024
    for r in range(0, size, block):
        rng = np.random.default_rng(r)
        rows = min(block, size - r)
        part = rng.exponential(size=(rows, size)).astype(np.float32)
        for c in range(block // 2, size, 4 * block // 3):  # targets along the block seams
            part[: min(24, rows), c : c + 30] = rng.exponential(size=(min(24, rows), 30)) * 25
        mm[r : r + rows] = part
        mm.flush()
    del mm


def run(path: str, detector: str, tile: int) -> None:
    import torch

    from torchsar.tiling import scene_objects

    torch.set_num_threads(1)
    scene = np.load(path, mmap_mode="r")
    table = scene_objects(scene, detector, tile=tile)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Linux: KiB
    print(peak, len(table))


if __name__ == "__main__":
    if sys.argv[1] == "write":
        write(sys.argv[2], int(sys.argv[3]))
    else:
        run(sys.argv[2], sys.argv[3], int(sys.argv[4]))
