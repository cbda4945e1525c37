"""The dataset-scale runner: one pass per detector over batches, states merged by addition.

Each batch is loaded once and given to every detector. Per detector the runner accumulates
pixel counts and the pixel ROC (:class:`~torchsar.metrics.RocAccumulator` over
``Detection.statistic``), then sends the detection through the shared discrimination stage
(:func:`torchsar.objects.discriminate`, the same rules for every detector), matches the
objects one-to-one to the ground truth and adds them to an
:class:`~torchsar.metrics.ObjectState`. Images of different sizes (folder datasets) are
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

from torchsar.metrics import (
    Matching,
    ObjectState,
    PixelCounts,
    RocAccumulator,
    match_batch,
    pixel_counts,
)
from torchsar.metrics.curves import OP_BIN
from torchsar.objects import ObjectRules, Objects, discriminate
from torchsar_eval.datasets.base import BadItemError
from torchsar_eval.detectors import DetectorSpec
from torchsar_eval.scoring import batch_truth, image_rows, pixel_areas

__all__ = [
    "DEFAULT_MATCH",
    "DEFAULT_RULES",
    "DetectorResult",
    "Scoring",
    "SkipBad",
    "batches",
    "evaluate",
]


DEFAULT_RULES = ObjectRules(closing=2, min_area=5)
"""The harness's discrimination defaults: a closing that joins a vehicle's scatterer
fragments, and no object smaller than 5 px."""
DEFAULT_MATCH = Matching(kind="centroid")
"""The harness's matching default: the prescreening rule (see the README)."""


@dataclass(frozen=True)
class Scoring:
    """How detections are scored: the discrimination rules, the matching rule and the
    bootstrap (the same for every detector of a run; defaults: the harness's)."""

    rules: ObjectRules = DEFAULT_RULES
    matching: Matching = DEFAULT_MATCH
    replicates: int = 100
    seed: int = 0

    def as_dict(self) -> dict:
        return {
            "objects": self.rules.as_dict(),
            "matching": self.matching.as_dict(),
            "bootstrap": {"replicates": self.replicates, "seed": self.seed},
        }


@dataclass
class DetectorResult:
    """Everything measured for one detector on one dataset."""

    spec: DetectorSpec
    scoring: Scoring = field(default_factory=Scoring)
    pixels: PixelCounts = field(default_factory=PixelCounts)
    roc: RocAccumulator = field(default_factory=RocAccumulator)
    objects: ObjectState = field(init=False)
    seconds: float = 0.0
    object_seconds: float = 0.0
    images: int = 0
    rows: list = field(default_factory=list)
    op_bin: int = OP_BIN
    skipped: list = field(default_factory=list)

    def __post_init__(self) -> None:
        self.objects = ObjectState(replicates=self.scoring.replicates, seed=self.scoring.seed)

    def add(
        self, statistic: Tensor, threshold: Tensor, det_mask: Tensor, batch: dict, truth
    ) -> Objects:
        """Accumulate one batch's detections (``truth``: :func:`torchsar_eval.scoring.batch_truth`);
        returns the batch's objects."""
        mask, ignore = batch["mask"], batch["ignore"]
        self.pixels = self.pixels + pixel_counts(det_mask, mask, ignore=ignore)
        self.roc.update(statistic, mask, ignore)
        t0 = time.perf_counter()
        obj = self.objects_of(statistic, threshold, batch)
        gt, info = truth
        m = match_batch(obj, gt, self.scoring.matching)
        self.objects.update(m, obj, gt, info)
        self.rows += image_rows(m, obj, gt, info)
        self.object_seconds += time.perf_counter() - t0
        return obj

    def __add__(self, other: DetectorResult) -> DetectorResult:
        """Merge the results of two disjoint parts of a dataset (e.g. shards, in order)."""
        if self.spec.name != other.spec.name or self.scoring != other.scoring:
            raise ValueError("cannot add results of different detectors or scoring settings")
        out = DetectorResult(self.spec, self.scoring, self.pixels + other.pixels,
                             self.roc + other.roc, op_bin=self.op_bin)  # fmt: skip
        out.objects = self.objects + other.objects
        out.seconds = self.seconds + other.seconds
        out.object_seconds = self.object_seconds + other.object_seconds
        out.images = self.images + other.images
        out.rows = self.rows + other.rows
        out.skipped = self.skipped + other.skipped
        return out

    def objects_of(self, statistic: Tensor, threshold: Tensor, batch: dict) -> Objects:
        """The discrimination stage of this run on one batch."""
        rules = self.scoring.rules
        area = pixel_areas(batch) if rules.units == "m2" else None
        return discriminate(statistic, threshold, rules=rules, pixel_area=area)


def _stack(items: list[dict]) -> dict:
    out = {
        k: torch.stack([it[k] for it in items]) for k in ("image", "mask", "instances", "ignore")
    }
    out["meta"] = [it["meta"] for it in items]
    return out


class SkipBad(Dataset):
    """A dataset whose unreadable items (:class:`~torchsar_eval.datasets.BadItemError`) are returned
    as ``{"bad": path, "error": message}`` markers instead of stopping the run."""

    def __init__(self, dataset: Dataset) -> None:
        self.dataset = dataset

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, i: int) -> dict:
        try:
            return self.dataset[i]
        except BadItemError as exc:
            return {"bad": str(exc.path), "error": str(exc)}


def batches(dataset: Dataset, batch_size: int, skipped: list | None = None) -> Iterator[dict]:
    """Yield stacked batches; consecutive images of different sizes split a batch; items
    marked bad by :class:`SkipBad` are left out and listed in ``skipped``."""
    loader = DataLoader(dataset, batch_size=batch_size, shuffle=False, collate_fn=list)
    for items in loader:
        group: list[dict] = []
        for it in items:
            if "bad" in it:
                if skipped is not None:
                    skipped.append((it["bad"], it["error"]))
                continue
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
    scoring: Scoring | None = None,
    name: str = "",
    progress: bool = True,
    desc: str = "",
    on_batch: Callable[[dict, dict], None] | None = None,
) -> list[DetectorResult]:
    """Run every detector over the dataset and accumulate its pixel and object states.

    Args:
        dataset: yields dicts with ``image``, ``mask``, ``instances``, ``ignore``, ``meta``.
        detectors: the detectors to run (with resolved parameters).
        batch_size: images per batch.
        preprocess: optional image stage applied once per batch before every detector (e.g. a
            speckle filter); its time is charged to every detector's ``ms_per_image``.
        scoring: discrimination, matching and bootstrap settings (default :class:`Scoring`).
        name: dataset name (part of each image's bootstrap key).
        progress: show a progress bar.
        desc: progress-bar label.
        on_batch: called as ``on_batch(batch, {detector: Objects})`` after each batch (e.g.
            a COCO exporter).
    """
    scoring = Scoring() if scoring is None else scoring
    results = [DetectorResult(spec, scoring) for spec in detectors]
    n_batches = -(-len(dataset) // batch_size) if len(dataset) else 0
    skipped: list = []
    for batch in tqdm(
        batches(dataset, batch_size, skipped),
        total=n_batches,
        desc=desc,
        disable=not progress,
        leave=False,
    ):
        x = batch["image"]
        t0 = time.perf_counter()
        if preprocess is not None:
            x = preprocess(x)
        t_pre = time.perf_counter() - t0
        t0 = time.perf_counter()
        truth = batch_truth(batch, name or desc)
        t_truth = (time.perf_counter() - t0) / max(len(results), 1)  # shared by the detectors
        found = {}
        for res in results:
            t0 = time.perf_counter()
            det = res.spec(x)
            res.seconds += time.perf_counter() - t0 + t_pre
            res.images += x.shape[0]
            res.object_seconds += t_truth
            found[res.spec.name] = res.add(det.statistic, det.threshold, det.mask, batch, truth)
        if on_batch is not None:
            on_batch(batch, found)
    for res in results:
        res.skipped = list(skipped)
    return results
