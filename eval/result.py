"""What a run measures of one detector on one dataset (:class:`DetectorResult`: pixel counts and
ROC, object state, per-image rows, timing; mergeable by ``+``) and how (:class:`Scoring`):
a detector's output becomes scored objects here (the shared discrimination stage, or its
own instances), is matched one-to-one and added to the states."""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np
import torch
from torch import Tensor

from torchsar.detection import Detection
from torchsar.metrics import (
    Matching,
    ObjectState,
    PixelCounts,
    RocAccumulator,
    match_batch,
)
from torchsar.metrics.assign import measured_as
from torchsar.metrics.coco_compat import CocoState
from torchsar.metrics.coco_inputs import coco_images
from torchsar.metrics.distance import LengthErrors
from torchsar.metrics.error_types import false_alarm_types
from torchsar.metrics.records import Records
from torchsar.metrics.scr import target_scr_db
from torchsar.objects import ObjectRules, Objects, discriminate
from torchsar.objects.discriminate import own_regions, single_threshold
from torchsar_eval import statefile
from torchsar_eval.detector import Detector
from torchsar_eval.errors import EvalError
from torchsar_eval.gallery import Cases, Gallery
from torchsar_eval.inputs import objects_from, seen_shape, truth_from
from torchsar_eval.scoring import (
    BOOTSTRAP_UNITS,
    image_infos,
    image_rows,
    pixel_areas,
    truth_from_targets,
)

__all__ = [
    "DEFAULT_MATCH",
    "DEFAULT_RULES",
    "STATE_FORMAT",
    "DetectorName",
    "DetectorResult",
    "Evaluator",
    "Scoring",
    "object_pixels",
    "pixel_view",
]


DEFAULT_RULES = ObjectRules(closing=2, min_area=5)
"""The harness's discrimination defaults: a closing that joins a vehicle's scatterer
fragments, and no object smaller than 5 px."""
DEFAULT_MATCH = Matching(kind="centroid")
"""The harness's matching default: the prescreening rule (see the README)."""
STATE_FORMAT = "torchsar-evaluator"
"""The ``format`` of :meth:`Evaluator.state_dict`."""


@dataclass(frozen=True)
class Scoring:
    """How detections are scored, the same for every detector of a run (defaults: the
    harness's).

    Attributes:
        rules: the discrimination stage (closing, size limits, floor) of detectors that
            return a statistic.
        matching: the matching rule of the operating point and the FROC.
        replicates: bootstrap replicates of the intervals (0: none).
        seed: bootstrap seed.
        bootstrap_unit: what the bootstrap resamples: ``"image"`` (each image), or
            ``"group"`` (the groups of images in ``meta["group"]``, e.g. the scene each
            image was cut from, so that images of one scene are drawn together; simulated
            images are grouped by clutter model; an image without a group is its own
            unit). Resampling needs many groups to mean anything. Every detector of a run
            gets the same resampled units, which makes the comparisons in ``paired.csv``
            paired.
        instances: ``"auto"`` scores each detector's own instances when it returns them
            (a region CFAR's regions, a CNN's boxes); ``"discriminate"`` sends every
            detector's statistic (or its objects' pixel scores) through the discrimination
            stage, for like-for-like comparisons.
        coco_compatible: also compute ``pycocotools``' 12 ``COCOeval.stats`` exactly (per
            category, 100 detections per image and category, COCO's area ranges).
    """

    rules: ObjectRules = DEFAULT_RULES
    matching: Matching = DEFAULT_MATCH
    replicates: int = 200
    seed: int = 0
    instances: str = "auto"
    coco_compatible: bool = False
    bootstrap_unit: str = "image"

    def __post_init__(self) -> None:
        if self.bootstrap_unit not in BOOTSTRAP_UNITS:
            raise EvalError(
                f"{{opt:bootstrap_unit}}{self.bootstrap_unit!r}: expected "
                f"{' or '.join(map(repr, BOOTSTRAP_UNITS))}"
            )
        if self.instances not in ("auto", "discriminate"):
            raise EvalError(
                f"{{opt:instances}}{self.instances!r}: expected 'auto' or 'discriminate'"
            )
        if (
            isinstance(self.replicates, bool)
            or not isinstance(self.replicates, int)
            or (self.replicates < 0)
        ):
            raise EvalError(
                f"bootstrap replicates must be an integer >= 0, got {self.replicates!r}"
            )

    def as_dict(self) -> dict:
        return {
            "objects": self.rules.as_dict(),
            "matching": self.matching.as_dict(),
            "bootstrap": {
                "replicates": self.replicates,
                "seed": self.seed,
                "unit": self.bootstrap_unit,
            },
            "instances": self.instances,
            "coco_compatible": self.coco_compatible,
        }


@dataclass(frozen=True)
class DetectorName:
    """What a saved :class:`DetectorResult` keeps of its detector."""

    name: str
    instances: str = "auto"
    saved: bool = False
    """Saved predictions (read from a file: no detection time to report)."""


def detector_name(detector) -> DetectorName:
    """What a saved state keeps of a detector (a :class:`DetectorName`, or anything without
    a callable, is kept by its fields)."""
    if not hasattr(detector, "fn"):
        return DetectorName(
            detector.name, detector.instances, bool(getattr(detector, "saved", False))
        )
    return DetectorName(
        detector.name, detector.instances, bool(getattr(detector.fn, "saved_predictions", False))
    )


@dataclass
class Evaluator:
    """Everything measured for one detector on one dataset, and the incremental evaluator a
    training loop calls: :meth:`update` with each batch's predictions and targets,
    :meth:`compute` for the tables (those of :func:`~torchsar_eval.evaluate`), ``+`` (or
    :meth:`merge`) for states of disjoint images (other processes, other splits, in any
    order), :meth:`state_dict` / :meth:`load_state_dict` to save and restore it as data.
    :func:`~torchsar_eval.evaluate` drives one per dataset and detector.

    ``calibrated`` says whether the operating point was chosen on a calibration split, at
    the score ``chosen`` (detections scoring above it count; ``None``: every detection);
    otherwise it is the objects' design point (:attr:`ObjectState.design_threshold`).
    ``pixel_level`` says whether pixel metrics were measured (not for boxes or points).
    ``gallery`` holds the detector's worst cases (:class:`~torchsar_eval.gallery.Gallery`).

    Args:
        detector: the row's name (or the harness's :class:`~torchsar_eval.Detector`).
        scoring: matching, discrimination and bootstrap (default :class:`Scoring`).

    Examples:
        >>> import torch
        >>> ev = Evaluator("cnn", Scoring(replicates=0))
        >>> targets = [{"boxes": torch.tensor([[2.0, 2, 10, 10]]), "image_id": 0}]
        >>> preds = [{"boxes": torch.tensor([[2.0, 2, 10, 10], [20, 20, 30, 30]]),
        ...           "scores": torch.tensor([0.9, 0.3])}]
        >>> ev.update(preds, targets)
        >>> s = ev.compute().summary.iloc[0]
        >>> int(s.tp), int(s.fp), round(float(s.ap50), 6)
        (1, 1, 1.0)
    """

    detector: Detector | DetectorName | str = "detector"
    scoring: Scoring = field(default_factory=Scoring)
    pixels: PixelCounts = field(default_factory=PixelCounts)
    roc: RocAccumulator = field(default_factory=RocAccumulator)
    objects: ObjectState = field(init=False)
    seconds: float = 0.0
    object_seconds: float = 0.0
    images: int = 0
    rows: list = field(default_factory=list)
    calibrated: bool = False
    chosen: float | None = None
    skipped: list = field(default_factory=list)
    pixel_level: bool = False
    default_class: str = "target"
    coco: CocoState | None = None
    coco_iou_type: str | None = None
    gallery: Gallery | None = None
    row_order: list = field(default_factory=list)
    """The order key of each per-image row added by :meth:`update` (rows are reported in
    image order, whatever order the batches came in)."""
    measured: list = field(default_factory=list)
    """How the pairs were measured, sorted (``"mask"``, ``"box"``, ``"point"``,
    ``"distance"``, ``"centroid"``: :func:`~torchsar.metrics.assign.measured_as`)."""

    def __post_init__(self) -> None:
        if isinstance(self.detector, str):
            self.detector = DetectorName(self.detector)
        if not isinstance(self.scoring, Scoring):
            raise EvalError(f"{{opt:scoring}}{self.scoring!r}: expected a torchsar_eval.Scoring")
        self.objects = ObjectState(replicates=self.scoring.replicates, seed=self.scoring.seed)
        if self.gallery is None:
            self.gallery = Gallery()
        if self.scoring.coco_compatible and self.coco is None:
            self.coco = CocoState()

    def __getstate__(self) -> dict:
        """Saved shard states hold the detector's name, not the detector (which may be a
        lambda, a network, a file reader): data only."""
        state = dict(self.__dict__)
        state["detector"] = detector_name(self.detector)
        state["rows"] = _row_columns(self.rows)
        return state

    def __setstate__(self, state: dict) -> None:
        state = dict(state)
        state["rows"] = _column_rows(state.get("rows", []))
        state.setdefault("measured", [])  # a state saved before rows said what they measured
        self.__dict__.update(state)

    @property
    def threshold(self) -> float | None:
        """The reported operating point: detections scoring above it count (``None``:
        every detection)."""
        return self.chosen if self.calibrated else self.objects.design_threshold

    def choose(self, threshold: float | None) -> None:
        """Report at ``threshold`` (chosen on a calibration split) instead of the design
        point."""
        self.calibrated, self.chosen = True, threshold

    # -- the incremental evaluator ---------------------------------------------------------

    def update(
        self,
        predictions,
        targets,
        *,
        images=None,
        box_format: str = "xyxy",
        categories: Mapping | None = None,
        threshold: float | None = None,
        mask_threshold: float = 0.5,
    ) -> None:
        """Add a batch: one prediction and one target per image (see
        :mod:`torchsar_eval.inputs` for what they may be: torchvision-style dicts of tensors
        or arrays, typed :class:`~torchsar_eval.items.Item` / ``Targets``).

        Args:
            predictions: per image ``{"boxes", "scores", "labels"?, "masks"?}`` (or
                ``"points"``); without labels, class-agnostic.
            targets: per image ``{"boxes", "labels"?, "masks"?, "iscrowd"?, "area"?,
                "image_id"?}``, or an ``Item`` / ``Targets``. ``image_id`` orders the images
                (ties in score, as pycocotools ranks them): give it when batches may come in
                any order or from several processes; by default the order they are added.
            images: the batch's intensity images ``(B, C, H, W)`` or ``(B, H, W)``
                (optional): the targets' signal-to-clutter ratios are measured on them.
            box_format: ``"xyxy"`` (torchvision), ``"xywh"`` (COCO) or ``"rc"``.
            categories: ``{label: name}`` for integer labels (default: the numbers).
            threshold: the operating threshold of the scores (``None``: every prediction
                counts at the operating point).
            mask_threshold: where probability masks are cut.

        Raises:
            EvalError: not one prediction per target, a malformed box, mask or label.
        """

        predictions, targets = list(predictions), list(targets)
        if len(predictions) != len(targets):
            raise EvalError(
                f"{len(predictions)} predictions for {len(targets)} targets: give one per image"
            )
        first = self.images
        opts = {
            "box_format": box_format,
            "categories": categories,
            "mask_threshold": mask_threshold,
        }
        if images is not None and len(images) != len(targets):
            raise EvalError(
                f"{{opt:images}} holds {len(images)} images for {len(targets)} "
                "targets: give one per image"
            )
        seen = [
            seen_shape(p, None if images is None else images[k]) for k, p in enumerate(predictions)
        ]
        truths = [truth_from(t, first + k, seen=seen[k], **opts) for k, t in enumerate(targets)]
        groups: dict[tuple[int, int], list[int]] = {}
        for k, (_, meta) in enumerate(truths):
            groups.setdefault(tuple(meta.shape), []).append(k)
        for shape, ks in groups.items():
            obj = objects_from([predictions[k] for k in ks], shape, threshold=threshold, **opts)
            self._update_group([truths[k] for k in ks], obj, shape, _planes(images, ks))
        self.images += len(targets)

    def _update_group(self, truths: list, obj: Objects, shape, image) -> None:
        """Add the images of one size (``image``: their ``(N, H, W)`` pixels, or ``None``)."""

        metas = [m.as_meta() for _, m in truths]
        spacing = np.array([m["pixel_spacing"] or (np.nan, np.nan) for m in metas], np.float64)
        gt = truth_from_targets([t for t, _ in truths], shape, spacing=spacing.reshape(-1, 2))
        if image is not None and len(gt):
            gt = replace(gt, scr_db=target_scr_db(image, gt.ids, gt.ignore, gt.box, gt.plane))
        info = image_infos(metas, self.detector.name, 1, shape, self.scoring.bootstrap_unit)
        self.add_objects(obj, gt, info)
        self.row_order += [int(m.index) for _, m in truths]

    def compute(self, dataset: str = "dataset"):
        """Every table of :func:`~torchsar_eval.evaluate` for what was added, as
        :class:`~torchsar_eval.Results` (no run folder; per-image rows in image order)."""
        # the tables need pandas: imported here, so that the worker processes, which
        # import this module, never load it
        import pandas as pd

        from torchsar_eval.results import Results, result_tables
        from torchsar_eval.tables import PER_IMAGE_COLUMNS

        tables = result_tables({dataset: [self]})
        rows = self.rows
        if len(self.row_order) == len(rows):
            rows = [rows[k] for k in np.argsort(np.array(self.row_order), kind="stable")]
        per_image = pd.DataFrame(
            [[dataset, self.detector.name, *r] for r in rows], columns=PER_IMAGE_COLUMNS
        )
        stats = {dataset: {"images": self.images, "scored": self.images}}
        return Results(tables, per_image=per_image, states={dataset: [self]}, stats=stats)

    @property
    def saved_predictions(self) -> bool:
        """Whether the detector is saved predictions (read from a file: no detection time
        to report)."""
        return detector_name(self.detector).saved

    @property
    def iou_type(self) -> str:
        """What the row's matching measured: ``"mask"``, ``"box"``, ``"mask+box"``,
        ``"point"``, ``"distance"``, ``"centroid"`` (``""`` before any target was seen)."""
        order = ("mask", "box", "point", "distance", "centroid")
        return "+".join(
            sorted(
                self.measured,
                key=lambda k: (k not in order, order.index(k) if k in order else 0, k),
            )
        )

    def merge(self, other: Evaluator) -> Evaluator:
        """``self + other``: the state of both sets of images (disjoint)."""
        return self + other

    def reset(self) -> None:
        """Forget every image added."""
        fresh = Evaluator(
            detector_name(self.detector), self.scoring, default_class=self.default_class
        )
        self.__dict__.update(fresh.__dict__)

    def state_dict(self) -> dict:
        """The state as data only (plain values and numpy arrays, no pickled object):
        ``{"format", "version", "tree", "arrays"}``; :meth:`load_state_dict` reads it
        back (only the harness's own state classes are rebuilt)."""
        tree, arrays = statefile.encode(self)
        return {"format": STATE_FORMAT, "version": 1, "tree": tree, "arrays": arrays}

    def load_state_dict(self, state: Mapping) -> None:
        """Restore a :meth:`state_dict` (replacing this evaluator's state).

        Raises:
            EvalError: not a state dict of an evaluator.
        """
        if not isinstance(state, Mapping) or state.get("format") != STATE_FORMAT:
            raise EvalError("{opt:state} is not an Evaluator.state_dict()")
        other = statefile.decode(state["tree"], list(state["arrays"]), "evaluator state")
        if not isinstance(other, Evaluator):
            raise EvalError("{opt:state} does not hold an evaluator")
        self.__dict__.update(other.__dict__)

    # -- the harness's batches --------------------------------------------------------------

    def add(self, out: Detection | Objects, batch: dict, truth) -> Objects:
        """Accumulate one batch's detector output (on the CPU; ``truth``:
        :func:`torchsar_eval.scoring.batch_truth`); returns the batch's objects."""
        mask, ignore = batch["mask"], batch["ignore"]
        if isinstance(out, Detection):
            counts = self.roc.update(out.statistic, mask, ignore, detected=out.mask)
            self.pixels = self.pixels + counts
            self.pixel_level = True
        elif _sparse_pixel_metrics(self, out, batch):
            self.pixel_level = True
        t0 = time.perf_counter()
        obj = self.objects_of(out, batch)
        self.object_seconds += time.perf_counter() - t0
        # images not read (saved predictions): no picture to crop
        self.add_objects(obj, *truth, image=None if batch.get("truth_only") else batch.get("image"))
        return obj

    def add_objects(self, obj: Objects, gt, info, *, image=None) -> None:
        """Accumulate scored objects against their ground truth (one entry of ``info`` per
        plane): the object-level states, the per-image rows, the worst cases (with the
        planes' ``image``, when there is one to crop) and the COCO state."""
        t0 = time.perf_counter()
        self._check_scale(obj.threshold if len(obj) else None, self.objects)
        m = match_batch(obj, gt, self.scoring.matching)
        self.measured = sorted({*self.measured, *measured_as(obj, gt, self.scoring.matching)})
        types = false_alarm_types(m, obj, gt, self.scoring.matching)
        self.objects.update(m, obj, gt, info, fa_types=types)
        self.rows += image_rows(m, obj, gt, info)
        if self.gallery is not None and image is not None:
            self.gallery.add(obj, gt, info, m, image, self.scoring.matching, types)
        if self.coco is not None:
            self._add_coco(obj, gt, info)
        self.object_seconds += time.perf_counter() - t0

    def _add_coco(self, obj: Objects, gt, info) -> None:
        """COCO's own evaluation of the batch: segm IoU for objects with masks (unless the
        run matches boxes or the ground truth is boxes), else bbox."""
        masks = obj.has_masks and self.scoring.matching.iou_kind == "mask"
        iou_type = "segm" if masks and not gt.box_only.any() else "bbox"
        if len(obj) and self.coco_iou_type not in (None, iou_type):
            raise EvalError(
                f"detector {self.detector.name}: COCO IoU type changes from "
                f"{self.coco_iou_type} to {iou_type} within a dataset"
            )
        if len(obj):
            self.coco_iou_type = iou_type
        orders = [p if i.order is None else i.order for p, i in enumerate(info)]
        self.coco.update(coco_images(obj, gt, orders, iou_type, self.default_class))

    def __add__(self, other: Evaluator) -> Evaluator:
        """Merge the results of two disjoint parts of a dataset (e.g. shards, in order)."""
        if self.detector.name != other.detector.name or self.scoring != other.scoring:
            raise ValueError("cannot add results of different detectors or scoring settings")
        out = Evaluator(
            self.detector,
            self.scoring,
            self.pixels + other.pixels,
            self.roc + other.roc,
            calibrated=self.calibrated,
            chosen=self.chosen,
            default_class=self.default_class,
        )
        if self.coco is not None:
            out.coco = self.coco + other.coco
            out.coco_iou_type = self.coco_iou_type or other.coco_iou_type
        if other.objects.thresholded:
            self._check_scale(other.objects.threshold, self.objects)
        out.objects = self.objects + other.objects
        out.seconds = self.seconds + other.seconds
        out.object_seconds = self.object_seconds + other.object_seconds
        out.images = self.images + other.images
        out.rows = self.rows + other.rows
        aligned = all(len(r.row_order) == len(r.rows) for r in (self, other))
        out.row_order = self.row_order + other.row_order if aligned else []
        out.skipped = self.skipped + other.skipped
        out.pixel_level = self.pixel_level or other.pixel_level
        out.measured = sorted({*self.measured, *other.measured})
        if self.gallery is not None and other.gallery is not None:
            out.gallery = self.gallery + other.gallery
        else:  # a state saved without one
            out.gallery = self.gallery or other.gallery
        return out

    def _check_scale(self, threshold: float | None, state) -> None:
        """Refuse objects whose operating threshold differs from the one already scored
        (a detector whose single design threshold changes between batches), naming the
        way out."""
        seen = state.threshold if state.thresholded else None
        if threshold is None or seen is None or threshold == seen:
            return
        raise EvalError(
            f"detector {self.detector.name}: its operating threshold changed from "
            f"{seen:.6g} to {threshold:.6g} between batches, so its scores would "
            "change scale: declare one for its objects (--param "
            f"{self.detector.name}.threshold=T) or score its statistic on "
            f"statistic / threshold (--param {self.detector.name}.scale=ratio; "
            "Python: Detector(..., scale='ratio'))"
        )

    def objects_of(self, out: Detection | Objects, batch: dict) -> Objects:
        """The scored objects of one batch: the detector's own instances (``Objects``, or a
        Detection's ``labels``), else (or when the run or the detector asks for it) the
        shared discrimination stage on its statistic."""
        own = "discriminate" not in (self.scoring.instances, self.detector.instances)
        if isinstance(out, Objects):
            if own:
                return out
            view = pixel_view(out)
            if view is None:
                raise EvalError(
                    f"detector {self.detector.name} returns {out.geometry}es, "
                    "which the discrimination stage cannot use: score its own "
                    "instances ({opt:instances}'auto')"
                )
            statistic = view[0]
            threshold = -np.inf if out.threshold is None else out.threshold
        else:
            if own and out.labels is not None:
                scale = self.score_scale(out.threshold)
                return own_regions(out.statistic, out.threshold, out.labels, scale=scale)
            statistic, threshold = out.statistic, out.threshold
        rules = self.scoring.rules
        area = pixel_areas(batch) if rules.units == "m2" else None
        return discriminate(
            statistic, threshold, rules=rules, pixel_area=area, scale=self.score_scale(threshold)
        )

    def score_scale(self, threshold) -> str:
        """The scale of the objects the discrimination stage makes of a statistic with this
        threshold: the detector's own statistic when the threshold is one finite value
        (unless the detector asks for ``scale="ratio"``), else statistic / threshold."""
        if self.detector.scale == "ratio" or single_threshold(threshold) is None:
            return "ratio"
        return "statistic"


def pixel_view(out: Detection | Objects) -> tuple[Tensor, Tensor] | None:
    """``(statistic, mask)`` of a detector output for the pixel metrics: a Detection's own,
    or for objects with masks each pixel's best object score (on the objects' own scale;
    ``-inf`` outside every object; the mask: pixels of objects above the operating
    threshold, or of every object when none is declared); ``None`` for boxes and points."""
    if isinstance(out, Detection):
        return out.statistic, out.mask
    sparse = object_pixels(out)
    if sparse is None:
        return None
    idx, best, level = sparse
    h, w = out.shape
    full = np.full(out.planes * h * w, -np.inf)
    full[idx] = best
    stat = torch.from_numpy(full.reshape(out.planes, 1, h, w))
    return stat, stat > level


def object_pixels(out: Objects) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The pixels the objects cover: ``(flat index, best score, level)`` with ``level`` the
    operating threshold (``-inf`` when none is declared); ``None`` for objects without
    masks."""
    if not out.has_masks:
        return None
    owner, idx = out.pixel_lists()
    h, w = out.shape
    best = np.full(out.planes * h * w, -np.inf)
    np.maximum.at(best, idx, out.score[owner])
    covered = np.zeros(best.size, bool)
    covered[idx] = True
    idx = np.flatnonzero(covered)
    return idx, best[idx], -np.inf if out.threshold is None else out.threshold


def _sparse_pixel_metrics(res: DetectorResult, out: Objects, batch: dict) -> bool:
    """Pixel counts and ROC of objects with masks from their pixels only (every other
    pixel is ``-inf``); ``False`` for objects without masks."""
    sparse = object_pixels(out)
    if sparse is None:
        return False
    idx, best, level = sparse
    target = batch["mask"].reshape(-1)
    ignore = batch["ignore"].reshape(-1)
    care = ~ignore
    n_target = int(torch.count_nonzero(target & care))
    n_clutter = int(torch.count_nonzero(care)) - n_target
    ti = torch.from_numpy(idx)
    t, ig = target[ti], ignore[ti]
    det = torch.from_numpy(best > level) & ~ig
    res.pixels = res.pixels + PixelCounts(
        int((det & t).sum()), int((det & ~t).sum()), n_target, n_clutter
    )
    res.roc.update_sparse(torch.from_numpy(best), t, ig, n_target, n_clutter)
    return True


def _row_columns(rows: list) -> dict | list:
    """Per-image rows ``(image, n_gt, tp, fp, fn, objects, max_score)`` as columns (a list
    of names, an int64 ``(n, 5)`` array, a float64 array): a few values to save instead of a
    structure per row. Rows of another shape stay a list."""
    if not all(len(r) == 7 and isinstance(r[0], str) for r in rows):
        return rows
    counts = np.array([r[1:6] for r in rows], dtype=np.int64).reshape(len(rows), 5)
    return {
        "image": [r[0] for r in rows],
        "counts": counts,
        "max_score": np.array([r[6] for r in rows], dtype=np.float64),
    }


def _column_rows(rows: dict | list) -> list:
    """The rows of :func:`_row_columns` again, as the tuples of plain values they were."""
    if not isinstance(rows, dict):
        return list(rows)
    counts = rows["counts"].tolist()
    return [
        (k, *c, s)
        for k, c, s in zip(rows["image"], counts, rows["max_score"].tolist(), strict=True)
    ]


DetectorResult = Evaluator
"""The harness's name of :class:`Evaluator` (one detector on one dataset)."""


def _planes(images, ks: list[int]):
    """Images ``ks`` of a batch as ``(N, H, W)`` float64 planes (first channel), or ``None``."""
    if images is None:
        return None
    x = images.detach().cpu().numpy() if hasattr(images, "detach") else np.asarray(images)
    x = x[:, 0] if x.ndim == 4 else x
    if x.ndim != 3:
        raise EvalError(f"{{opt:images}} must be (B, C, H, W) or (B, H, W), got shape {x.shape}")
    return x[ks].astype(np.float64)


for _cls in (
    DetectorResult,
    DetectorName,
    Scoring,
    ObjectRules,
    Matching,
    PixelCounts,
    ObjectState,
    Records,
    LengthErrors,
    Gallery,
    Cases,
    RocAccumulator,
):  # the classes a state file (a shard, a state_dict) may hold
    statefile.register(_cls)
statefile.register(CocoState, transient=("_cache", "_consolidated"))
