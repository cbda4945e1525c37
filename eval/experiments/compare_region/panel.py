"""A PNG panel of detections: rows are images, columns the image, the ground truth and each
detector's mask (red over the image)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from torchsar_eval.detector import Detector
from torchsar_eval.plots import pyplot, save

__all__ = ["db_display", "detection_panel"]

DB_PERCENTILES = (2.0, 99.8)
"""The dB range shown: these percentiles of the image's positive pixels."""


def db_display(img: torch.Tensor | np.ndarray) -> np.ndarray:
    """An image in dB mapped to [0, 1] over a robust range: the percentiles
    :data:`DB_PERCENTILES` of its *positive* pixels, so that zeros (a display-scaled chip's
    black pixels, a masked border) neither stretch the range to -120 dB and wash the
    image out nor take part in it (they show black).

    Examples:
        >>> x = np.r_[np.zeros(50), np.geomspace(1e-3, 1, 950)]
        >>> d = db_display(x)
        >>> float(d[:50].max()), float(np.median(d[50:])) > 0.3
        (0.0, True)
    """
    a = img.double().numpy() if isinstance(img, torch.Tensor) else np.asarray(img, np.float64)
    pos = a[np.isfinite(a) & (a > 0)]
    if pos.size == 0:
        return np.zeros(a.shape)
    db = 10 * np.log10(np.where(np.isfinite(a) & (a > 0), a, pos.min()))
    lo, hi = np.percentile(10 * np.log10(pos), DB_PERCENTILES)
    out = np.clip((db - lo) / max(hi - lo, 1e-9), 0, 1)
    out[~(np.isfinite(a) & (a > 0))] = 0.0
    return out


def _overlay(ax, img: np.ndarray, mask: np.ndarray, title: str) -> None:
    rgb = np.repeat(img[..., None], 3, axis=-1)
    rgb[mask] = 0.45 * rgb[mask] + 0.55 * np.array([1.0, 0.1, 0.1])
    ax.imshow(rgb, interpolation="nearest")
    ax.set_title(title, fontsize=8)
    ax.axis("off")


def detection_panel(items: list[dict], specs: list[Detector], path: Path) -> None:
    """Draw ``items`` (dataset dicts with ``image``, ``mask``) against every detector."""
    plt = pyplot()
    cols = 2 + len(specs)
    fig, axes = plt.subplots(len(items), cols, figsize=(2.1 * cols, 2.2 * len(items)))
    axes = np.atleast_2d(axes)
    for row, item in zip(axes, items, strict=True):
        x = item["image"][None]
        img = db_display(item["image"][0])
        row[0].imshow(img, cmap="gray", interpolation="nearest")
        row[0].set_title(item["meta"].get("name", "image"), fontsize=8)
        row[0].axis("off")
        _overlay(row[1], img, item["mask"][0].numpy(), "ground truth")
        for ax, spec in zip(row[2:], specs, strict=True):
            _overlay(ax, img, spec(x).mask[0, 0].cpu().numpy(), spec.name)
    save(fig, path)
