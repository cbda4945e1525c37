"""The detector output type: the contract of every CFAR variant, the region-growing detector
and the moving-target pipeline (re-exported as ``torchsar.cfar.Detection`` and
``torchsar.cfar.detection_from``); and :class:`DetectorSpec`, what a built-in detector's
module declares about itself (every registry is built from these declarations)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import torch
from torch import Tensor

__all__ = ["WINDOW", "Detection", "DetectorSpec", "detection_from"]

WINDOW: Mapping[str, Any] = {"guard": 2, "train": 4, "pfa": 1e-3}
"""The default window and false-alarm rate the evaluator records for the window CFARs."""


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


@dataclass(frozen=True)
class DetectorSpec:
    """A built-in detector as its module declares it (the module's ``SPEC``): the one place
    that names it. The evaluator's registry, the CFAR design thresholds, the command line's
    choices and the report's colours are all read from these declarations.

    Attributes:
        name: its name in the tables and on the command line (``"ca"``).
        detect: the detector ``detect(images, **options) -> Detection``.
        order: its position in the default run, which is also its colour in the report's
            palette (distinct for every built-in).
        options: the options the evaluator records (and passes) by default.
        threshold: its design threshold from its options (``threshold(**options) ->
            float``), for the CFARs; ``None`` for a detector without one.

    Examples:
        >>> spec = DetectorSpec("mine", lambda x: None, order=99)
        >>> spec.name, dict(spec.options), spec.threshold
        ('mine', {}, None)
    """

    name: str
    detect: Callable[..., Detection]
    order: int
    options: Mapping[str, Any] = field(default_factory=dict)
    threshold: Callable[..., float] | None = None
