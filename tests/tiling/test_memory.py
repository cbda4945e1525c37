"""Peak memory of tiled runs is bounded by the tile, not the scene (measured in fresh
processes: ``ru_maxrss``, which also counts the memmap pages read)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

LIMIT = int(2.5 * 2**30)
ROOT = Path(__file__).resolve().parents[2]


def _python(*args: str) -> str:
    out = subprocess.run(
        [sys.executable, "-m", "tests.tiling._rss", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
        timeout=3600,
    )
    return out.stdout


def _peak(path: Path, detector: str, tile: int) -> tuple[int, int]:
    peak, objects = _python("run", str(path), detector, str(tile)).split()
    return int(peak), int(objects)


@pytest.mark.integration
def test_tiled_objects_from_a_memmap_in_a_fresh_process(tmp_path):
    path = tmp_path / "scene.npy"
    _python("write", str(path), "1024")
    peak, objects = _peak(path, "ca", 256)
    assert objects > 0 and peak < LIMIT


@pytest.mark.slow
def test_peak_memory_does_not_grow_with_the_scene(tmp_path):
    small, large = tmp_path / "small.npy", tmp_path / "large.npy"
    _python("write", str(small), "512")
    _python("write", str(large), "4096")  # 64x the pixels: 64 MB float32, 128 MB float64
    p_small, n_small = _peak(small, "ca", 256)
    p_large, n_large = _peak(large, "ca", 256)
    assert n_large > n_small > 0
    assert p_large < LIMIT
    # the memmap pages read (64 MB, counted by ru_maxrss) plus less than a float32 copy
    assert p_large - p_small < (64 + 48) * 2**20


@pytest.mark.slow
def test_region_cfar_on_a_16k_scene_stays_under_2_5_gb(tmp_path):
    path = tmp_path / "scene16k.npy"
    _python("write", str(path), "16384")
    peak, objects = _peak(path, "region", 1024)
    assert objects > 100  # the planted targets are found
    assert peak < LIMIT, f"peak RSS {peak / 2**30:.2f} GB"
