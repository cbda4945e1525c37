"""The detector output type: the contract of every CFAR variant, the region-growing detector
and the moving-target pipeline (re-exported as ``torchsar.cfar.Detection`` and
``torchsar.cfar.detection_from``)."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["Detection", "detection_from"]


@dataclass(frozen=True)
class Detection:
    """Result of a detector on a batch ``(B, C, H, W)``.

    Attributes:
        mask: bool ``(B, C, H, W)``, the detections at the design operating point. Always
            ``mask == statistic > threshold``.
        statistic: float ``(B, C, H, W)``; larger means more target-like. The evaluator sweeps
            a global threshold over it to trace a whole ROC from one pass. Pixels that cannot
            be tested (invalid cell under test, no valid training cell) hold ``-inf``.
        threshold: float tensor broadcastable to ``statistic`` (usually 0-dim): the design
            threshold, e.g. the CA factor ``alpha`` for the design ``pfa``.
        labels: optional int ``(B, C, H, W)`` region ids (0 = none, 1..n per image) for
            region-based detectors.
    """

    mask: Tensor
    statistic: Tensor
    threshold: Tensor
    labels: Tensor | None = None


def detection_from(
    statistic: Tensor, threshold: float | Tensor, labels: Tensor | None = None
) -> Detection:
    """Build a :class:`Detection`, deriving ``mask = statistic > threshold``.

    Examples:
        >>> d = detection_from(torch.tensor([[[[0.5, 2.0]]]]), 1.0)
        >>> d.mask.tolist()
        [[[[False, True]]]]
    """
    thr = torch.as_tensor(threshold, dtype=statistic.dtype, device=statistic.device)
    return Detection(mask=statistic > thr, statistic=statistic, threshold=thr, labels=labels)
