"""Detectors defined outside torchsar, as a user writes them (imported by path in tests)."""

from __future__ import annotations

import numpy as np
import torch
from scipy import ndimage

from torchsar.cfar import detection_from
from torchsar.objects import Objects


class RatioNet(torch.nn.Module):
    """A tiny network: each pixel over the mean of its ``window`` x ``window``
    neighbourhood, as a score map with a design threshold."""

    def __init__(self, window: int = 5, level: float = 4.0) -> None:
        super().__init__()
        self.pool = torch.nn.AvgPool2d(
            window, stride=1, padding=window // 2, count_include_pad=False
        )
        self.level = level

    def forward(self, x: torch.Tensor):
        return detection_from(x / self.pool(x).clamp_min(1e-12), self.level)


def bright_boxes(x: torch.Tensor, k: float = 6.0) -> Objects:
    """A box around each component brighter than ``k`` x the image median, with a
    probability-like score in [0, 1) from its peak contrast."""
    b, c, h, w = x.shape
    boxes, scores = [], []
    for plane in x.reshape(b * c, h, w).numpy():
        median = float(np.median(plane)) or 1.0
        labels, n = ndimage.label(plane > k * median)
        found = ndimage.find_objects(labels)
        peaks = ndimage.maximum(plane, labels, np.arange(1, n + 1)) if n else []
        boxes.append(
            np.array(
                [[s[0].start, s[1].start, s[0].stop, s[1].stop] for s in found], dtype=np.float64
            ).reshape(-1, 4)
        )
        scores.append(1.0 - np.exp(-np.asarray(peaks, dtype=np.float64) / median / 20.0))
    return Objects.from_boxes(boxes, scores, shape=(h, w))
