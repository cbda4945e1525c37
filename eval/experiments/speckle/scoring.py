"""Scoring of ``torchsar-eval speckle``: quality metrics per filter and window.

For every filter of :data:`torchsar.speckle.FILTERS` (and the unfiltered image as the
``none`` baseline) at every window size, each image of a dataset is filtered and scored:

- ``enl``: median equivalent number of looks of the filtered intensity over homogeneous
  ``tile x tile`` tiles: tiles whose clean reflectivity is flat (coefficient of variation
  < 0.02) when the clean image is known, else the quarter of tiles with the lowest noisy
  coefficient of variation; tiles touching targets or ignored pixels are never used.
- ``ratio_mean``, ``ratio_var``: moments of the ratio image ``noisy / filtered`` (ideal 1
  and ``1 / L``).
- ``edge_ratio``: no-reference gradient ratio of filtered to noisy amplitude.
- with a clean reflectivity only: ``epi`` (Sattar's edge preservation index), ``psnr_db``
  and ``ssim``, on amplitudes (square roots of intensity), data range = clean amplitude
  ``max - min`` per image.
- ``ms_per_mpix``: filter wall time per megapixel after one warm-up call (current torch
  thread setting; single images, so per-call overhead counts on small chips).

Image metrics are averaged over images; ENL is the median over the pooled tiles.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass

import pandas as pd
import torch
from torch import Tensor

import torchsar as ts
from torchsar.metrics import edge_preservation, edge_ratio, enl, psnr, ratio_moments, ssim

__all__ = [
    "COLUMNS",
    "Sample",
    "apply_filter",
    "homogeneous_tiles",
    "samples",
    "score_dataset",
]

COLUMNS = [
    "dataset",
    "filter",
    "window",
    "looks",
    "images",
    "enl",
    "ratio_mean",
    "ratio_var",
    "edge_ratio",
    "epi",
    "psnr_db",
    "ssim",
    "ms_per_mpix",
]
CLEAN_ONLY = ("epi", "psnr_db", "ssim")
FLAT_CV = 0.02  # clean tiles flatter than this count as homogeneous (bias on ENL < 2% at 50)


@dataclass(frozen=True)
class Sample:
    """One image to filter: intensity ``(1, C, H, W)``, optional clean reflectivity, the
    pixels to keep out of homogeneity tiles (targets and ignored), the speckle looks if
    known, and a box ``(r0, c0, r1, c1)`` of interest for the panel (or None)."""

    image: Tensor
    clean: Tensor | None
    exclude: Tensor
    looks: float | None
    box: tuple[int, int, int, int] | None


def samples(dataset) -> Iterator[Sample]:
    """The dataset's images as :class:`Sample`; items with a ``clean`` entry (simulated
    datasets) give the clean reflectivity."""
    for i in range(len(dataset)):
        item = dataset[i]
        meta = item.get("meta", {})
        clean = item["clean"][None] if item.get("clean") is not None else None
        looks = (meta.get("clutter") or {}).get("looks")
        boxes = meta.get("boxes") or []
        yield Sample(
            image=item["image"][None],
            clean=clean,
            exclude=(item["mask"] | item["ignore"])[None],
            looks=None if looks is None else float(looks),
            box=tuple(int(v) for v in boxes[0]) if boxes else None,
        )


def _tiles(x: Tensor, tile: int) -> Tensor:
    """Non-overlapping ``tile x tile`` tiles of ``(1, C, H, W)`` as ``(N, 1, tile, tile)``."""
    h, w = (x.shape[-2] // tile) * tile, (x.shape[-1] // tile) * tile
    if h == 0 or w == 0:
        return x.new_zeros((0, 1, tile, tile))
    t = x[..., :h, :w].unfold(-2, tile, tile).unfold(-2, tile, tile)
    return t.reshape(-1, 1, tile, tile)


def _cv(t: Tensor) -> Tensor:
    flat = t.to(torch.float64).flatten(1)
    if flat.shape[0] == 0:
        return flat.new_zeros(0)
    mean = flat.mean(1)
    return flat.std(1, correction=0) / torch.where(mean > 0, mean, torch.ones_like(mean))


def homogeneous_tiles(s: Sample, *, tile: int) -> Tensor:
    """Bool ``(N,)`` selection of homogeneous tiles (see the module docstring)."""
    free = ~_tiles(s.exclude, tile).flatten(1).any(1)
    if s.clean is not None:
        return free & (_cv(_tiles(s.clean, tile)) < FLAT_CV)
    cv = _cv(_tiles(s.image, tile))
    if not bool(free.any()):
        return free
    return free & (cv <= torch.quantile(cv[free], 0.25))


def apply_filter(name: str, s: Sample, *, window: int, looks: float) -> tuple[Tensor, float]:
    """Filtered intensity and the wall time in seconds (``none``: the image itself)."""
    if name == "none":
        return s.image.float(), 0.0
    t0 = time.perf_counter()
    out = ts.speckle.FILTERS[name](s.image, window=window, looks=looks)
    return out, time.perf_counter() - t0


def _image_metrics(s: Sample, f: Tensor) -> dict[str, float]:
    r_mean, r_var = ratio_moments(f, s.image)
    row = {
        "ratio_mean": r_mean.mean().item(),
        "ratio_var": r_var.mean().item(),
        "edge_ratio": edge_ratio(f.sqrt(), s.image.sqrt()).mean().item(),
    }
    if s.clean is not None:
        fa, ca = f.sqrt(), s.clean.sqrt()
        row["epi"] = edge_preservation(fa, ca).mean().item()
        row["psnr_db"] = psnr(fa, ca).mean().item()
        row["ssim"] = ssim(fa, ca).mean().item() if min(ca.shape[-2:]) >= 11 else math.nan
    return row


def score_filter(
    items: list[Sample], name: str, *, window: int, looks: float | None, tile: int
) -> dict[str, float]:
    """Metrics of one filter at one window over the images (see the module docstring)."""
    rows, enls, seconds, pixels = [], [], 0.0, 0
    if items:  # untimed warm-up call (first-call allocations are not the filter's cost)
        apply_filter(name, items[0], window=window, looks=looks or items[0].looks or 1.0)
    for s in items:
        lk = looks if looks is not None else (s.looks or 1.0)
        f, dt = apply_filter(name, s, window=window, looks=lk)
        seconds += dt
        pixels += s.image.numel()
        rows.append(_image_metrics(s, f))
        sel = homogeneous_tiles(s, tile=tile)
        if bool(sel.any()):
            enls.append(enl(_tiles(f, tile)[sel]).flatten())
    df = pd.DataFrame(rows)
    out = {k: float(df[k].mean()) if k in df else math.nan for k in COLUMNS[6:12]}
    out["enl"] = float(torch.cat(enls).double().median()) if enls else math.nan
    out["ms_per_mpix"] = seconds * 1e3 / (pixels / 1e6) if pixels and name != "none" else 0.0
    return out


def score_dataset(
    dataset_name: str,
    items: list[Sample],
    filters: list[str],
    windows: list[int],
    *,
    looks: float | None = None,
    tile: int = 32,
) -> pd.DataFrame:
    """One row per (filter, window), plus the unfiltered ``none`` baseline."""
    known = {s.looks for s in items}
    shown = looks if looks is not None else (known.pop() if len(known) == 1 else math.nan)
    rows = []
    for name, window in [("none", 0), *[(f, w) for f in filters for w in windows]]:
        row = {"dataset": dataset_name, "filter": name, "window": window}
        row.update(looks=shown if shown is not None else 1.0, images=len(items))
        row.update(score_filter(items, name, window=window, looks=looks, tile=tile))
        rows.append(row)
    return pd.DataFrame(rows, columns=COLUMNS)
