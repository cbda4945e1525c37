"""Scoring saved predictions from an annotation file without pixels: a shard of a ``coco:`` or
``voc:`` dataset whose detectors are all saved boxes or points is scored from the
annotations and the predictions alone, every image at once: no image is read, no item is
stacked, no pixel plane is allocated (box targets and box detections are compared as
boxes; only segmentations and don't-care masks are decoded). The states are those of the
item-by-item path (tested table for table); pixel metrics, measured signal-to-clutter
ratios and the gallery need pixels and are left out, as they are for any saved boxes.
"""

from __future__ import annotations

import time

import numpy as np

from torchsar.objects import Objects
from torchsar_eval.datasets.base import BadItemError
from torchsar_eval.items import spacings
from torchsar_eval.result import DetectorResult
from torchsar_eval.scoring import image_infos, truth_from_targets

__all__ = ["objects_only", "score_objects"]


def _base(dataset):
    """The dataset under the run's wrappers (truth-only, skip-bad)."""
    while hasattr(dataset, "dataset") and not hasattr(dataset, "truth_targets"):
        dataset = dataset.dataset
    return dataset


def _table(det):
    """A detector's saved-predictions table when it holds boxes or points, else ``None``."""
    table = getattr(det.fn, "table", None)
    geometry = getattr(table, "geometry", None)
    return table if geometry in ("box", "point") else None


def objects_only(job) -> bool:
    """Whether a shard job can be scored without pixels (see the module docstring)."""
    return (
        job.preprocess is None
        and hasattr(_base(job.dataset), "truth_targets")
        and job.scoring.instances != "discriminate"
        and bool(job.detectors)
        and all(_table(d) is not None and d.instances != "discriminate" for d in job.detectors)
        and not any(getattr(d.fn, "_point_offset", None) is not None for d in job.detectors)
    )


def _objects(det, items: list[int], shape: tuple[int, int]) -> Objects:
    """The saved predictions of dataset items ``items`` (planes in that order)."""
    fn, table = det.fn, _table(det)
    r, counts = fn.rows_for(items)
    plane = np.repeat(np.arange(len(items)), counts)
    names = getattr(fn, "_classes", None)
    common = {"plane": plane, "planes": len(items), "classes": None if names is None else names[r]}
    if table.geometry == "box":
        obj = Objects.from_boxes(table.box[r], table.score[r], shape=shape, **common)
        area = table.declared_area
        return obj.with_declared_area(None if area is None else area[r])
    length = None if table.length_m is None else table.length_m[r]
    return Objects.from_points(
        table.point[r], table.score[r], shape=shape, length_m=length, **common
    )


def score_objects(job, indices: list[int], name: str) -> list[DetectorResult]:
    """Every detector of ``job`` scored on dataset items ``indices`` (see the module
    docstring); images of one size are matched together."""
    ds = _base(job.dataset)
    results = [
        DetectorResult(d, job.scoring, default_class=job.default_class) for d in job.detectors
    ]
    for r in results:
        r.gallery = None
    stacked = getattr(ds, "truth_batch", None)
    groups = stacked(indices) if stacked is not None else None
    skipped: list = []
    if groups is None:  # item by item (segmentations to decode, bad items to skip)
        groups, skipped = _truth_by_item(ds, indices, job.execution.skip_bad)
    for r in results:
        r.skipped = list(skipped)
    done: list[int] = []
    for shape, items, gt, metas in groups:
        done += items
        info = image_infos(metas, name, 1, shape, job.scoring.bootstrap_unit)
        for res in results:
            t0 = time.perf_counter()
            obj = _objects(res.detector, items, shape)
            res.seconds += time.perf_counter() - t0
            res.images += len(items)
            res.add_objects(obj, gt, info)
    order = np.argsort(np.array(done, np.int64), kind="stable")
    for res in results:  # per-image rows in dataset order, as the item path writes them
        res.rows = [res.rows[k] for k in order]
    return results


def _truth_by_item(ds, indices: list[int], skip_bad: bool) -> tuple[list[tuple], list]:
    """``([(shape, items, GroundTruth, metas)], skipped)`` from each item's targets (a bad
    item raises, or with ``skip_bad`` is listed as ``(path, message)``)."""
    by_shape: dict[tuple[int, int], list] = {}
    skipped = []
    for i in indices:
        try:
            targets, shape, meta = ds.truth_targets(i)
        except BadItemError as exc:
            if not skip_bad:
                raise
            skipped.append((str(exc.path), str(exc)))
            continue
        by_shape.setdefault(shape, []).append((i, targets, {**meta, "index": i}))
    groups = []
    for shape, group in by_shape.items():
        metas = [m for _, _, m in group]
        spacing = spacings(metas)
        gt = truth_from_targets(
            [t for _, t, _ in group],
            shape,
            spacing=spacing,
            box_only=np.array([m.get("gt") == "box" for m in metas]),
        )
        groups.append((shape, [i for i, _, _ in group], gt, metas))
    return groups, skipped
