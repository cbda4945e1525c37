"""The before/after panel of ``torchsar-eval speckle``: crops in dB on one colour scale."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from torchsar_eval.experiments.speckle.scoring import Sample, apply_filter
from torchsar_eval.plots import save

__all__ = ["despeckling_panel"]


def _crop(s: Sample, size: int) -> tuple[slice, slice]:
    h, w = s.image.shape[-2:]
    if s.box is not None:
        cr, cc = (s.box[0] + s.box[2]) // 2, (s.box[1] + s.box[3]) // 2
    else:
        cr, cc = h // 2, w // 2
    r0 = min(max(cr - size // 2, 0), max(h - size, 0))
    c0 = min(max(cc - size // 2, 0), max(w - size, 0))
    return slice(r0, r0 + size), slice(c0, c0 + size)


def despeckling_panel(
    s: Sample, filters: list[str], path: Path, *, window: int, looks: float, size: int = 160
) -> None:
    """Before/after crops in dB (clean if known, noisy, every filter) on one colour scale,
    written to ``path``."""
    rows, cols = _crop(s, size)
    shown = ([("clean", s.clean)] if s.clean is not None else []) + [("noisy", s.image)]
    for n in filters:
        shown.append((f"{n} {window}x{window}", apply_filter(n, s, window=window, looks=looks)[0]))
    db = [(t, 10 * np.log10(x[0, 0, rows, cols].double().numpy() + 1e-10)) for t, x in shown]
    ref = db[0][1] if s.clean is not None else db[-1][1]  # clean, else a filtered crop
    vmin, vmax = np.percentile(ref, [1, 99.8])
    ncol = 4
    nrow = math.ceil(len(db) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.2 * ncol, 3.3 * nrow), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, (title, img) in zip(axes.flat, db, strict=False):
        ax.imshow(img, cmap="gray", vmin=vmin, vmax=vmax)
        ax.set_title(title, fontsize=9)
    h, w = db[0][1].shape
    fig.suptitle(f"intensity (dB), crop {h}x{w}, looks {looks:g}", fontsize=10)
    save(fig, path)
