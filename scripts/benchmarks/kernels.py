"""Benchmark cases: the window kernels against memory speed and against scipy.

- ``ca 1024x1024 x16 vs one 64 MiB copy``: sixteen CA-CFAR calls on a 1024x1024 float32
  image (4 MiB each, 64 MiB together) against one copy of a 64 MiB float32 tensor (larger
  than the caches): the ratio is "memory copy time of the image's bytes / CA time" (1/3 is
  "CA within 3x a copy of its bytes").
- speckle filters (Lee, Kuan, enhanced Lee, Frost; 7x7 window) at 256x256 and 512x512
  against the box-filter Lee of ``speckle.py`` (two ``uniform_filter`` calls); the
  megapixels per second are the image size over the printed time.
- OS-CFAR 512x512 (g=2, t=4, 144-cell ring) against ``scipy.ndimage.rank_filter`` with the
  same ring footprint (issue target: the reciprocal of the ratio at most 0.05), and its
  mask alone by counting (``os_mask``) against the same reference.

Run: ``python scripts/benchmark.py --topic kernels``.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Callable
from functools import partial
from pathlib import Path

import torch
from scipy import ndimage

import torchsar as ts


def _sibling(name: str):
    spec = importlib.util.spec_from_file_location(f"bench_{name}", Path(__file__).with_name(name))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _copy(src: torch.Tensor, dst: torch.Tensor) -> None:
    dst.copy_(src)


def _ca16(x: torch.Tensor) -> None:
    for _ in range(16):
        ts.cfar.ca(x, guard=2, train=4)


def cases() -> list[tuple[str, Callable[[], object], Callable[[], object]]]:
    gen = torch.Generator().manual_seed(0)
    x = torch.empty(1, 1, 1024, 1024).exponential_(generator=gen)
    big = torch.rand(16 * 1024 * 1024, generator=gen)
    out = [
        (
            "ca 1024x1024 f32 (g=2,t=4) x16 vs one 64 MiB copy",
            partial(_ca16, x),
            partial(_copy, big, torch.empty_like(big)),
        )
    ]
    lee = _sibling("speckle.py").scipy_lee
    for size in (256, 512):
        img = torch.empty(1, 1, size, size).exponential_(generator=gen)
        a = img[0, 0].numpy()
        for name in ("lee", "kuan", "enhanced_lee", "frost"):
            fn = ts.speckle.FILTERS[name]
            out.append(
                (
                    f"speckle.{name} {size}x{size} f32 w=7 vs scipy uniform_filter Lee",
                    partial(fn, img, window=7),
                    partial(lee, a),
                )
            )
    family = _sibling("cfar_family.py")
    img = torch.empty(1, 1, 512, 512).exponential_(generator=gen)
    fp = family.ring_footprint(2, 4)
    rank = round(0.75 * int(fp.sum()))
    out.append(
        (
            "os 512x512 (g=2,t=4,N=144) vs scipy rank_filter",
            partial(ts.cfar.os, img, guard=2, train=4),
            partial(ndimage.rank_filter, img[0, 0].numpy(), rank - 1, footprint=fp),
        )
    )
    out.append(
        (
            "os_mask 512x512 (g=2,t=4,N=144: counting) vs scipy rank_filter",
            partial(ts.cfar.os_mask, img, guard=2, train=4),
            partial(ndimage.rank_filter, img[0, 0].numpy(), rank - 1, footprint=fp),
        )
    )
    return out
