"""The dataset-scale runner: one pass per detector over batches, counts merged by addition.

Each batch is loaded once and given to every detector; per detector the runner accumulates
pixel counts and object counts at the design operating point (``Detection.mask``) and a
:class:`~torchsar.metrics.RocAccumulator` over ``Detection.statistic``, so one pass gives a
detector's summary and its whole ROC. Images of different sizes (folder datasets) are
grouped into same-size sub-batches.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import torch
from torch import Tensor
from torch.utils.data import DataLoader, Dataset
from tqdm.auto import tqdm

from eval.detectors import DetectorSpec
from torchsar.metrics import (
    ObjectCounts,
    PixelCounts,
    RocAccumulator,
    default_object_grid,
    default_pixel_grid,
    merged_grid,
    object_counts,
    pixel_counts,
)

__all__ = ["DetectorResult", "batches", "evaluate"]


@dataclass
class DetectorResult:
    """Everything measured for one detector on one dataset."""

    spec: DetectorSpec
    pixels: PixelCounts = field(default_factory=PixelCounts)
    objects: ObjectCounts = field(default_factory=ObjectCounts)
    roc: RocAccumulator | None = None
    seconds: float = 0.0
    images: int = 0

    def add(self, det_mask: Tensor, statistic: Tensor, threshold: Tensor, batch: dict) -> None:
        """Accumulate one batch's detections."""
        mask, inst, ignore = batch["mask"], batch["instances"], batch["ignore"]
        self.pixels = self.pixels + pixel_counts(det_mask, mask, ignore)
        self.objects = self.objects + object_counts(det_mask, inst, ignore)
        if self.roc is None:
            obj = default_object_grid(float(threshold.max()))
            self.roc = RocAccumulator(merged_grid(default_pixel_grid(), obj), obj)
        self.roc.update(statistic, mask, inst, ignore)


def _stack(items: list[dict]) -> dict:
    out = {
        k: torch.stack([it[k] for it in items]) for k in ("image", "mask", "instances", "ignore")
    }
    out["meta"] = [it["meta"] for it in items]
    return out


def batches(dataset: Dataset, batch_size: int) -> Iterator[dict]:
    """Yield stacked batches; consecutive images of different sizes split a batch."""
    loader = DataLoader(dataset, batch_size=batch_size, shuffle=False, collate_fn=list)
    for items in loader:
        group: list[dict] = []
        for it in items:
            if group and it["image"].shape != group[0]["image"].shape:
                yield _stack(group)
                group = []
            group.append(it)
        if group:
            yield _stack(group)


def evaluate(
    dataset: Dataset,
    detectors: list[DetectorSpec],
    *,
    batch_size: int = 16,
    preprocess: Callable[[Tensor], Tensor] | None = None,
    progress: bool = True,
    desc: str = "",
) -> list[DetectorResult]:
    """Run every detector over the dataset and accumulate its counts and ROC.

    Args:
        dataset: yields dicts with ``image``, ``mask``, ``instances``, ``ignore``, ``meta``.
        detectors: the detectors to run (with resolved parameters).
        batch_size: images per batch.
        preprocess: optional image stage applied once per batch before every detector (e.g. a
            speckle filter); its time is charged to every detector's ``ms_per_image``.
        progress: show a progress bar.
        desc: progress-bar label.
    """
    results = [DetectorResult(spec) for spec in detectors]
    n_batches = -(-len(dataset) // batch_size) if len(dataset) else 0
    for batch in tqdm(
        batches(dataset, batch_size), total=n_batches, desc=desc, disable=not progress, leave=False
    ):
        x = batch["image"]
        t0 = time.perf_counter()
        if preprocess is not None:
            x = preprocess(x)
        t_pre = time.perf_counter() - t0
        for res in results:
            t0 = time.perf_counter()
            det = res.spec(x)
            res.seconds += time.perf_counter() - t0 + t_pre
            res.images += x.shape[0]
            res.add(det.mask, det.statistic, det.threshold, batch)
    return results
