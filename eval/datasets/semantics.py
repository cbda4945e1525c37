"""Ground-truth semantics: how labels become target / ignore, how instances are formed,
and a sanity check that warns when instances look split or merged."""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
from scipy.ndimage import find_objects
from skimage.measure import label

__all__ = [
    "INSTANCE_MODES",
    "SHADOW_MODES",
    "boxes_of",
    "check_instance_counts",
    "form_instances",
    "looks_merged",
    "looks_split",
    "split_labels",
]

SHADOW_MODES = ("ignore", "clutter", "target")
INSTANCE_MODES = ("components", "one-per-image", "idmap")
SPLIT_GAP = 3  # px: instances whose boxes come this close form one cluster
SPLIT_SHARE = 0.2  # warn when at least this share of checked images looks split


def split_labels(lab: np.ndarray, shadow: str) -> tuple[np.ndarray, np.ndarray]:
    """Target and ignore masks of a ``0 clutter / 1 target / 2 shadow`` label map."""
    target = (lab == 1) | ((lab == 2) & (shadow == "target"))
    return target, (lab == 2) & (shadow == "ignore")


def form_instances(target: np.ndarray, mode: str, idmap: np.ndarray | None = None) -> np.ndarray:
    """int32 instance ids of the target pixels: 8-connected components, one per image, or
    an id map (restricted to target pixels and renumbered ``1..K`` in order)."""
    if mode == "one-per-image":
        return target.astype(np.int32)
    if mode == "idmap":
        ids = np.where(target, idmap, 0)
        _, inv = np.unique(ids, return_inverse=True)
        return (inv.reshape(ids.shape) + (0 if (ids == 0).any() else 1)).astype(np.int32)
    return label(target, connectivity=2).astype(np.int32)


def boxes_of(instances: np.ndarray) -> list[tuple[int, int, int, int]]:
    """End-exclusive ``(r0, c0, r1, c1)`` of each id ``1..K`` (empty ids get ``(0,0,0,0)``)."""
    slices = find_objects(instances, max_label=int(instances.max(initial=0)))
    return [
        (s[0].start, s[1].start, s[0].stop, s[1].stop) if s is not None else (0, 0, 0, 0)
        for s in slices
    ]


def _clusters(boxes: Sequence[tuple[float, float, float, float]], gap: float) -> int:
    """Number of groups of boxes chained by gaps of at most ``gap`` pixels."""
    parent = list(range(len(boxes)))

    def find(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    for i, a in enumerate(boxes):
        for j in range(i):
            b = boxes[j]
            if max(a[0] - b[2], b[0] - a[2], a[1] - b[3], b[1] - a[3]) <= gap:
                parent[find(i)] = find(j)
    return len({find(i) for i in range(len(boxes))})


def looks_split(boxes: Sequence[tuple[float, float, float, float]]) -> bool:
    """Several instances whose boxes all chain within a few pixels: one object, split?"""
    return len(boxes) >= 2 and _clusters(boxes, SPLIT_GAP) == 1


def looks_merged(instances: np.ndarray) -> bool:
    """An instance made of pieces far apart (more than 10 % of the image side): merged?"""
    gap = max(8, 0.1 * max(instances.shape))
    for i, box in enumerate(find_objects(instances), start=1):
        if box is None:
            continue
        parts = label(instances[box] == i, connectivity=2)
        if parts.max() > 1 and _clusters(boxes_of(parts), gap) > 1:
            return True
    return False


def check_instance_counts(name: str, items: Sequence[dict], mode: str) -> None:
    """Warn (naming the dataset and counts) when the checked items' instances look split
    (one object cut into several nearby instances) or merged (far pieces in one instance)."""
    n = len(items)
    split = sum(looks_split(it["meta"]["boxes"]) for it in items)
    merged = sum(looks_merged(it["instances"][0].numpy()) for it in items)
    if n and split >= max(1, SPLIT_SHARE * n):
        warnings.warn(
            f"dataset {name}: {split} of the first {n} images have several instances that all "
            f"lie within {SPLIT_GAP} px of each other (instances={mode}); if each image holds "
            "one target, use ?instances=one-per-image",
            stacklevel=3,
        )
    if merged:
        warnings.warn(
            f"dataset {name}: {merged} of the first {n} images have an instance made of pieces "
            f"far apart (instances={mode}); check that instances are not merged",
            stacklevel=3,
        )
