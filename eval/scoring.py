"""From a dataset batch to what the object scorer needs: ground truth, per-image facts and the
per-image rows of ``per_image.csv``."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from torchsar.metrics.assign import BatchMatch
from torchsar.metrics.matching import GroundTruth, ground_truth
from torchsar.metrics.object_state import ImageInfo, above
from torchsar.metrics.scr import target_scr_db
from torchsar.metrics.truth import Regions
from torchsar.objects import Objects

__all__ = [
    "BOOTSTRAP_UNITS",
    "batch_truth",
    "declared_boxes",
    "image_infos",
    "image_rows",
    "known_scr",
    "pixel_areas",
    "truth_from_targets",
]

BOOTSTRAP_UNITS = ("image", "group")
"""What the bootstrap resamples: images, or groups of images (``meta["group"]``, e.g. the
scene an image was cut from; simulated images: their clutter model; an image without a
group is its own unit)."""


def _planes(batch: dict) -> tuple[int, int]:
    b, c = batch["instances"].shape[:2]
    return b, c


def _spacing(meta: dict) -> tuple[float, float] | None:
    sp = meta.get("pixel_spacing")
    if sp is None and meta.get("pixel_m") is not None:
        sp = (meta["pixel_m"], meta["pixel_m"])
    return None if sp is None else (float(sp[0]), float(sp[1]))


def _group(meta: dict) -> str | None:
    clutter = meta.get("clutter")
    return f"clutter={clutter['model']}" if isinstance(clutter, dict) else meta.get("group")


def declared_boxes(meta: dict) -> bool:
    """Whether the instances' boxes are the annotations' (box-only ground truth, COCO and
    VOC files) rather than their masks' bounding boxes."""
    return meta.get("gt") == "box" or meta.get("box_source") == "annotation"


def known_scr(meta: dict) -> list | None:
    """The known signal-to-clutter ratio in dB of each instance (``None`` where unknown):
    ``meta["scr_db"]`` (one per id), else each ``meta["targets"][j]["scr_db"]`` (the
    simulator's); ``None`` when the item declares none."""
    declared = meta.get("scr_db")
    if declared is None:
        targets = meta.get("targets")
        if not isinstance(targets, list | tuple):
            return None
        declared = [t.get("scr_db") if isinstance(t, dict) else None for t in targets]
        if all(v is None for v in declared):
            return None
    return [None if v is None else float(v) for v in declared]


def batch_truth(
    batch: dict, dataset: str, unit: str = "image"
) -> tuple[GroundTruth, list[ImageInfo]]:
    """Ground truth of a batch (one plane per image channel) and each plane's facts: the
    image key (the image name, so a store and its source agree), image-level class,
    group, area in km^2, order in the dataset (``meta["index"]`` and the channel) and the
    bootstrap's unit (``unit="group"``: the image's group). The ground truth carries each
    instance's measured SCR (on ``batch["image"]``, the intensity before any
    preprocessing: :func:`torchsar.metrics.scr.target_scr_db`), its known SCR
    (:func:`known_scr`) and which planes' ignore pixels are radar shadow
    (``meta["shadow"] == "ignore"``)."""
    b, c = _planes(batch)
    h, w = batch["instances"].shape[-2:]
    metas = [m for m in batch["meta"] for _ in range(c)]
    box_only = np.array([m.get("gt") == "box" for m in metas])
    spacing = [_spacing(m) or (np.nan, np.nan) for m in metas]
    if "targets" in batch:
        given = [t for t in batch["targets"] for _ in range(c)]
        shadow = np.array([m.get("shadow") == "ignore" for m in metas])
        sp = np.array(spacing, np.float64).reshape(len(metas), 2)
        gt = truth_from_targets(given, (h, w), box_only=box_only, spacing=sp, shadow=shadow)
        return _with_scr(gt, batch, b * c, h, w), image_infos(metas, dataset, c, (h, w), unit)
    inst = batch["instances"].reshape(b * c, h, w).cpu().numpy()
    ignore = batch["ignore"].reshape(b * c, h, w).cpu().numpy()
    known = [known_scr(m) for m in metas]
    gt = ground_truth(
        inst,
        ignore,
        classes=[list(m.get("classes") or []) for m in metas],
        boxes=[list(m.get("boxes") or []) if declared_boxes(m) else [] for m in metas],
        box_only=box_only,
        spacing=np.array(spacing, dtype=np.float64).reshape(len(metas), 2),
        lengths=[list(m.get("lengths_m") or []) for m in metas],
        areas=[list(m.get("areas") or []) for m in metas],
        known_scr_db=[k or [] for k in known] if any(known) else None,
        shadow=np.array([m.get("shadow") == "ignore" for m in metas]),
    )
    return _with_scr(gt, batch, b * c, h, w), image_infos(metas, dataset, c, (h, w), unit)


def _with_scr(gt: GroundTruth, batch: dict, n: int, h: int, w: int) -> GroundTruth:
    """The ground truth with each target's SCR measured on the batch's images (when it has
    images: items read for their ground truth only have none to measure)."""
    if batch.get("image") is None or not len(gt) or batch.get("truth_only"):
        return gt
    image = batch["image"].reshape(n, h, w).cpu().numpy()
    return replace(gt, scr_db=target_scr_db(image, gt.ids, gt.ignore, gt.box, gt.plane))


def image_infos(
    metas: list[dict], dataset: str, c: int, shape: tuple[int, int], unit: str = "image"
) -> list[ImageInfo]:
    """Each plane's facts (:class:`~torchsar.metrics.object_state.ImageInfo`): its key (the
    image name, ``#channel`` with several channels), image class, group, area in km², order
    in the dataset and bootstrap unit."""
    h, w = shape
    info = []
    for k, m in enumerate(metas):
        sp = _spacing(m)
        name = str(m.get("name", f"{dataset}/{k}")) + (f"#{k % c}" if c > 1 else "")
        km2 = None if sp is None else h * w * sp[0] * sp[1] / 1e6
        index = m.get("index")
        order = None if index is None else int(index) * c + k % c
        group = _group(m)
        boot = f"group:{group}" if unit == "group" and group else None
        info.append(ImageInfo(name, m.get("class"), group, km2, order, boot))
    return info


def truth_from_targets(
    targets: list, shape: tuple[int, int], *, box_only=None, spacing=None, shadow=None
) -> GroundTruth:
    """:class:`~torchsar.metrics.GroundTruth` of a stack of planes of ``shape`` from each
    plane's :class:`~torchsar_eval.items.Targets` (as given: nothing painted)."""

    h, w = shape
    n = [len(t) for t in targets]
    k = [len(t.crowd_classes) for t in targets]
    plane = np.repeat(np.arange(len(targets)), n)
    cplane = np.repeat(np.arange(len(targets)), k)
    cat = lambda xs: np.concatenate(xs) if xs else np.zeros(0)  # noqa: E731
    return GroundTruth.build(
        plane,
        cat([t.boxes for t in targets]).reshape(-1, 4),
        planes=len(targets),
        shape=(h, w),
        classes=[c for t in targets for c in t.classes],
        pixels=[p for t in targets for p in t.pixels],
        crowd=Regions.build(
            cplane,
            cat([t.crowd_boxes for t in targets]).reshape(-1, 4),
            shape=(h, w),
            classes=[c for t in targets for c in t.crowd_classes],
            pixels=[p for t in targets for p in t.crowd_pixels],
        ),
        box_only=box_only,
        spacing=spacing,
        length_m=cat([t.lengths_m for t in targets]),
        declared_area=cat([t.areas for t in targets]),
        known_scr_db=(
            cat([t.scr_db for t in targets])
            if any(np.isfinite(t.scr_db).any() for t in targets)
            else None
        ),
        shadow=shadow,
    )


def pixel_areas(batch: dict) -> np.ndarray | None:
    """Square metres per pixel for each plane, or ``None`` when any image lacks a spacing."""
    c = _planes(batch)[1]
    out = []
    for m in batch["meta"]:
        sp = _spacing(m)
        if sp is None:
            return None
        out += [sp[0] * sp[1]] * c
    return np.array(out)


def image_rows(m: BatchMatch, obj: Objects, gt: GroundTruth, info: list[ImageInfo]) -> list:
    """One row per plane at the design operating point (scores above the objects'
    threshold, or every object when they declare none):
    ``(image, n_gt, tp, fp, fn, objects, max_score)``."""
    n = len(info)
    at_op = above(obj.score, obj.threshold)
    tp = np.bincount(obj.plane[at_op & (m.op >= 0)], minlength=n)
    fp = np.bincount(obj.plane[at_op & (m.op == -1)], minlength=n)
    n_gt = np.bincount(gt.plane, minlength=n)
    count = np.bincount(obj.plane, minlength=n)
    best = np.full(n, -np.inf)
    np.maximum.at(best, obj.plane, obj.score)
    return [
        (
            i.key,
            int(n_gt[p]),
            int(tp[p]),
            int(fp[p]),
            int(n_gt[p] - tp[p]),
            int(count[p]),
            float(best[p]),
        )
        for p, i in enumerate(info)
    ]
