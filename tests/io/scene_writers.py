"""Hand-made TIFF scenes for the scene-reader tests (written with tifffile directly, not by
the code under test), and a seeded set of windows that cross tiles and reach the edges."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import tifffile

GEOGRAPHIC_KEYS = [1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326]


def scene_array(shape: tuple[int, int], dtype: str, seed: int = 0) -> np.ndarray:
    """Seeded samples of any supported dtype (complex with distinct real/imaginary parts)."""
    rng = np.random.default_rng(seed)
    dt = np.dtype(dtype)
    if dt.kind == "c":
        return (rng.normal(size=shape) + 1j * rng.normal(size=shape)).astype(dt)
    if dt.kind == "f":
        return rng.normal(size=shape).astype(dt)
    info = np.iinfo(dt)
    return rng.integers(info.min, info.max, size=shape, endpoint=True, dtype=dt)


def write_complex_int16(path: Path, re: np.ndarray, im: np.ndarray, **kwargs) -> Path:
    """Complex int16 samples (SampleFormat 5, 32 bits): int16 pairs written as int32, then
    the SampleFormat tag overwritten."""
    pairs = np.stack([re, im], axis=-1).astype("<i2")
    tifffile.imwrite(path, pairs.view("<i4")[..., 0], **kwargs)
    with tifffile.TiffFile(path, mode="r+b") as tif:
        tif.pages[0].tags[339].overwrite(5)
    return path


def windows(shape: tuple[int, int], tile: tuple[int, int], n: int, seed: int) -> list:
    """Windows on tile boundaries, at the image edges, whole, single pixel, and random."""
    h, w = shape
    th, tw = tile
    fixed = [
        (0, h, 0, w),
        (0, 1, 0, 1),
        (h - 1, h, w - 1, w),
        (min(th, h) - 1, min(th + 1, h), min(tw, w) - 1, min(tw + 1, w)),
        (0, min(th, h), 0, min(tw, w)),
        (h - 3, h, 0, w),
        (0, h, w - 5, w),
        (th, min(2 * th, h), tw, min(2 * tw, w)),
    ]
    rng = np.random.default_rng(seed)
    for _ in range(n):
        r0, r1 = np.sort(rng.integers(0, h + 1, 2))
        c0, c1 = np.sort(rng.integers(0, w + 1, 2))
        fixed.append((int(r0), int(r1) + (r0 == r1 and r1 < h), int(c0), int(c1)))
    return fixed
