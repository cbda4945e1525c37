"""A PNG panel of detections: rows are images, columns the image, the ground truth and each
detector's mask (red over the image)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import torch

from torchsar_eval.detector import Detector
from torchsar_eval.plots import save

__all__ = ["detection_panel"]


def _db(img: torch.Tensor) -> np.ndarray:
    a = 10 * np.log10(img.double().numpy() + 1e-12)
    lo, hi = np.percentile(a, [1, 99.5])
    return np.clip((a - lo) / max(hi - lo, 1e-9), 0, 1)


def _overlay(ax, img: np.ndarray, mask: np.ndarray, title: str) -> None:
    rgb = np.repeat(img[..., None], 3, axis=-1)
    rgb[mask] = 0.45 * rgb[mask] + 0.55 * np.array([1.0, 0.1, 0.1])
    ax.imshow(rgb, interpolation="nearest")
    ax.set_title(title, fontsize=8)
    ax.axis("off")


def detection_panel(items: list[dict], specs: list[Detector], path: Path) -> None:
    """Draw ``items`` (dataset dicts with ``image``, ``mask``) against every detector."""
    cols = 2 + len(specs)
    fig, axes = plt.subplots(len(items), cols, figsize=(2.1 * cols, 2.2 * len(items)))
    axes = np.atleast_2d(axes)
    for row, item in zip(axes, items, strict=True):
        x = item["image"][None]
        img = _db(item["image"][0])
        row[0].imshow(img, cmap="gray", interpolation="nearest")
        row[0].set_title(item["meta"].get("name", "image"), fontsize=8)
        row[0].axis("off")
        _overlay(row[1], img, item["mask"][0].numpy(), "ground truth")
        for ax, spec in zip(row[2:], specs, strict=True):
            _overlay(ax, img, spec(x).mask[0, 0].cpu().numpy(), spec.name)
    save(fig, path)
