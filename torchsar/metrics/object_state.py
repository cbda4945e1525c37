"""Object-level scoring state of one detector on one dataset: per-detection records, exact.

An :class:`ObjectState` keeps one record per image, per detection and per ground-truth
target (:mod:`torchsar.metrics.records`) and computes every metric from them when it is
read: the operating point (precision, recall, F1, FoM, false alarms per image and per km²,
mean IoU, fragmentation, length score), COCO AP50 and AP50:95, the FROC at every score
level, Pd at fixed false alarms per image, the partial AUC (reading rules in
:mod:`torchsar.metrics.curves`), the breakdowns (class, size bin, image class, group), the
false-alarm types, Pd per signal-to-clutter ratio bin, and the Poisson-bootstrap replicates
of the headline metrics (:func:`replicate_metrics`: each replicate weights the records of
each resampling unit by its weight, :mod:`torchsar.metrics.bootstrap`).

An operating point is a score threshold on the detector's own scale: the detections scoring
``> threshold`` count (``None``: every detection counts). No score is binned, so a strictly
increasing map of a detector's scores (with its threshold) changes no number, however the
scores are spread (probabilities within 1e-12 of 1, logits, ratios of 1e300).

States of disjoint sets of images merge with ``+`` (records concatenated); any split of a
dataset into batches, shards or workers, merged in any order, gives equal states and
identical tables. Memory: :data:`~torchsar.metrics.records.BYTES_PER_DETECTION` bytes per
detection, :data:`~torchsar.metrics.records.BYTES_PER_TARGET` per target and
:data:`~torchsar.metrics.records.BYTES_PER_IMAGE` per image.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from torchsar.metrics.assign import BatchMatch
from torchsar.metrics.bootstrap import unit_hash
from torchsar.metrics.curves import coco_ap_rows, levels
from torchsar.metrics.distance import LengthErrors
from torchsar.metrics.intervals import Interval, headline_intervals
from torchsar.metrics.matching import COCO_IOUS, GroundTruth
from torchsar.metrics.records import (
    DETECTION,
    IMAGE,
    NOT_FA,
    TARGET,
    Records,
    bit,
    bits,
    consolidate,
    plane_ranks,
)
from torchsar.metrics.replicates import FA_LEVELS, Resampled, replicate_metrics
from torchsar.objects import Objects

__all__ = [
    "FA_LEVELS",
    "NO_CLASS",
    "ImageInfo",
    "ObjectState",
    "above",
    "ratios",
    "size_bin",
]

NO_CLASS = "(no image class)"
"""Where a false alarm without a class of its own or of its image is counted."""
SCORED, TARGET_OP, IGNORED = 0, 1, 2  # ``op`` of a detection record: false alarm, TP, ignored


@dataclass(frozen=True)
class ImageInfo:
    """What the scorer needs to know about one plane beyond its pixels."""

    key: str
    cls: str | None = None
    group: str | None = None
    km2: float | None = None
    order: int | None = None
    """Global order of the plane in its dataset (ties in score are ranked by it, as
    ``pycocotools`` ranks them by image id; unique per image); default: the count of images
    the state had before the batch, plus the plane's position in it."""
    boot_key: str | None = None
    """The bootstrap's resampling unit of the plane (planes with the same ``boot_key`` get the
    same replicate weights, e.g. the images of one scene); default: ``key``."""


def size_bin(area: np.ndarray, edges: tuple[float, ...]) -> np.ndarray:
    """Size bin index of each area: bin ``i`` is ``[edges[i-1], edges[i])`` (half-open)."""
    return np.searchsorted(np.asarray(edges, dtype=np.float64), area, side="right")


def above(score: np.ndarray, threshold: float | None) -> np.ndarray:
    """Which scores count at an operating point: ``score > threshold`` (all for ``None``).

    Examples:
        >>> above(np.array([0.2, 0.5, 0.9]), 0.5).tolist(), above(np.array([0.2]), None).tolist()
        ([False, False, True], [True])
    """
    s = np.asarray(score)
    return np.ones(s.shape, bool) if threshold is None else s > threshold


def ratios(tp: int, fp: int, n_gt: int, images: int) -> dict:
    """TP, FP, FN, precision, recall, F1 and false alarms per image of counts.

    Examples:
        >>> r = ratios(3, 1, 4, 2)
        >>> r["precision"], r["recall"], r["f1"], r["fa_per_image"]
        (0.75, 0.75, 0.75, 0.5)
    """
    nan = float("nan")
    return {
        "tp": tp,
        "fp": fp,
        "fn": n_gt - tp,
        "precision": tp / (tp + fp) if tp + fp else nan,
        "recall": tp / n_gt if n_gt else nan,
        "f1": 2 * tp / (2 * tp + fp + (n_gt - tp)) if (tp + fp + n_gt) else nan,
        "fa_per_image": fp / images if images else nan,
    }


def _op_status(op: np.ndarray) -> np.ndarray:
    """Matching statuses (instance >= 0, -1 unmatched, -2 ignored) as record ``op`` codes."""
    return np.where(op >= 0, TARGET_OP, np.where(op == -2, IGNORED, SCORED)).astype(np.uint8)


@dataclass(eq=False)
class ObjectState:
    """Object-level state of one detector on one dataset (see the module docstring).

    Args:
        replicates: bootstrap replicates (0: no intervals).
        seed: bootstrap seed.
        size_edges: size-bin edges in pixels (default COCO's 32^2 and 96^2, half-open bins
            ``small``, ``medium``, ``large``).
        size_names: one name per bin.
    """

    replicates: int = 100
    seed: int = 0
    size_edges: tuple[float, ...] = (32.0**2, 96.0**2)
    size_names: tuple[str, ...] = ("small", "medium", "large")
    thresholded: bool | None = None
    threshold: float | None = None
    ap_kind: str | None = None
    ap_areas: int | None = None
    """Area ranges the AP statuses cover (``all``, small, medium, large; 1 for points)."""
    by_class: bool | None = None
    """Whether the detections were matched within their class (AP: the mean over classes)."""
    parts: list[Records] = field(default_factory=list)
    added: int = 0
    """Images added by :meth:`update` (the default order key of the next ones)."""
    scr_sources: tuple[str, ...] = ()
    """The signal-to-clutter ratio sources the ground truth gave (``measured`` on the image,
    ``known`` from the data): a source never given has no rows."""

    def __post_init__(self) -> None:
        if len(self.size_names) != len(self.size_edges) + 1:
            raise ValueError("size_names needs one name more than size_edges")
        self._cache: dict = {}

    # -- accumulation ------------------------------------------------------------------------

    def update(
        self,
        m: BatchMatch,
        obj: Objects,
        gt: GroundTruth,
        info: list[ImageInfo],
        *,
        fa_types: np.ndarray | None = None,
    ) -> None:
        """Add one matched batch (``info``: one entry per plane; ``fa_types``: each
        detection's false-alarm type, -1 where none, see
        :func:`~torchsar.metrics.error_types.false_alarm_types`)."""
        self._declare(m, obj)
        names: dict[str, int] = {}

        def name(n: str | None) -> int:
            return -1 if n is None else names.setdefault(str(n), len(names))

        def codes(values: np.ndarray) -> np.ndarray:
            """:func:`name` of many class names at once."""
            uniq, inv = np.unique(np.asarray(values, dtype=str), return_inverse=True)
            return np.array([name(u) for u in uniq.tolist()], np.int64)[inv].reshape(-1)

        images = self._image_records(gt, info, name)
        dets = np.zeros(len(obj), DETECTION)
        dets["score"], dets["image"], dets["rank"] = obj.score, obj.plane, plane_ranks(obj.plane)
        flat = m.ap.reshape(m.ap.shape[0] * m.ap.shape[1], len(obj))
        dets["ap_tp"], dets["ap_ig"] = bits(flat >= 0), bits(flat == -2)
        dets["op"], dets["iou"] = _op_status(m.op), m.op_iou
        types = np.full(len(obj), -1) if fa_types is None else np.asarray(fa_types)
        dets["fa_type"] = np.where(types >= 0, types, NOT_FA)
        dets["size"] = size_bin(obj.area, self.size_edges)
        if obj.classes is not None:
            dets["label"] = codes(obj.classes) if len(obj) else []
        else:
            dets["label"] = -1
        targets = self._target_records(m, obj, gt, codes)
        self.parts.append(Records(images, dets, targets, list(names)))
        self.added += len(info)
        self._cache.clear()

    def _declare(self, m: BatchMatch, obj: Objects) -> None:
        """What the objects say about their operating point and AP (the same in every
        batch)."""
        if self.ap_areas is not None and m.ap.shape[0] != self.ap_areas:
            raise ValueError("AP statuses of different area ranges in one state")
        self.ap_areas = int(m.ap.shape[0])
        if not len(obj):
            return
        if self.by_class is not None and m.by_class != self.by_class:
            raise ValueError(
                "detections with and without classes in one state: give every "
                "detection a class, or match class-agnostic"
            )
        self.by_class = bool(m.by_class)
        declared = obj.threshold is not None
        if self.thresholded is not None and (self.thresholded, self.threshold) != (
            declared,
            obj.threshold,
        ):
            raise ValueError("objects with different operating thresholds in one state")
        self.thresholded, self.threshold = declared, obj.threshold
        if self.ap_kind is not None and m.ap_kind != self.ap_kind:
            raise ValueError(f"AP of kinds {self.ap_kind} and {m.ap_kind} in one state")
        self.ap_kind = m.ap_kind

    def _image_records(self, gt: GroundTruth, info: list[ImageInfo], name) -> np.ndarray:
        out = np.zeros(len(info), IMAGE)
        out["order"] = [self.added + p if i.order is None else i.order for p, i in enumerate(info)]
        out["unit"] = np.array([unit_hash(i.boot_key or i.key) for i in info], dtype=np.uint64)
        out["n_gt"] = np.bincount(gt.plane, minlength=len(info))[: len(info)]
        out["group"] = [name(i.group) if i.group else -1 for i in info]
        out["cls"] = [name(i.cls) if i.cls else -1 for i in info]
        out["km2"] = [np.nan if i.km2 is None else float(i.km2) for i in info]
        return out

    def _target_records(self, m: BatchMatch, obj: Objects, gt: GroundTruth, codes) -> np.ndarray:
        n, hit = len(gt), m.gt_det >= 0
        out = np.zeros(n, TARGET)
        out["image"], out["index"] = gt.plane, plane_ranks(gt.plane)
        det = np.maximum(m.gt_det, 0)
        out["found"] = np.where(hit, obj.score[det] if len(obj) else 0.0, np.nan)
        out["size"] = size_bin(gt.area, self.size_edges)
        out["label"] = codes(gt.classes) if len(gt) else []
        out["coco_area"] = gt.coco_area
        out["touch"] = m.overlaps
        nan = np.full(n, np.nan)
        out["scr"] = nan if gt.scr_db is None else gt.scr_db
        out["scr_known"] = nan if gt.known_scr_db is None else gt.known_scr_db
        out["length"] = nan if gt.length_m is None else gt.length_m
        if obj.length_m is not None and len(obj):
            out["found_length"] = np.where(hit, obj.length_m[det], np.nan)
        else:
            out["found_length"] = np.nan
        given = {"measured"} if gt.scr_db is not None else set()
        if gt.known_scr_db is not None and not np.isnan(gt.known_scr_db).all():
            given.add("known")
        self.scr_sources = _sources(set(self.scr_sources) | given)
        return out

    # -- merging -----------------------------------------------------------------------------

    def _settings(self) -> tuple:
        return (self.replicates, self.seed, self.size_edges, self.size_names)

    def _declared(self) -> tuple:
        return (self.thresholded, self.threshold, self.ap_kind, self.ap_areas, self.by_class)

    def __add__(self, other: ObjectState) -> ObjectState:
        if self._settings() != other._settings():
            raise ValueError("cannot add ObjectStates with different settings")
        mine, theirs = (self.thresholded, self.threshold), (other.thresholded, other.threshold)
        if None not in (self.thresholded, other.thresholded) and mine != theirs:
            raise ValueError("cannot add states with different operating thresholds")
        for k in ("ap_kind", "ap_areas", "by_class"):
            a, b = getattr(self, k), getattr(other, k)
            if None not in (a, b) and a != b:
                raise ValueError(f"cannot add states of different {k}")
        first = self if self.thresholded is not None else other
        pick = {
            k: getattr(self, k) if getattr(self, k) is not None else getattr(other, k)
            for k in ("ap_kind", "ap_areas", "by_class")
        }
        out = ObjectState(
            replicates=self.replicates,
            seed=self.seed,
            size_edges=self.size_edges,
            size_names=self.size_names,
            thresholded=first.thresholded,
            threshold=first.threshold,
            **pick,
            parts=[*self.parts, *other.parts],
            added=self.added + other.added,
            scr_sources=_sources(set(self.scr_sources) | set(other.scr_sources)),
        )
        return out

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ObjectState):
            return NotImplemented
        a, b = self.records, other.records
        same = (self._settings(), self._declared(), self.scr_sources) == (
            other._settings(),
            other._declared(),
            other.scr_sources,
        )
        return (
            same
            and a.names == b.names
            and all(
                getattr(a, k).tobytes() == getattr(b, k).tobytes()  # NaN equals NaN here
                for k in ("images", "detections", "targets")
            )
        )

    def __getstate__(self) -> dict:
        state = {k: v for k, v in self.__dict__.items() if k != "_cache"}
        state["parts"] = [self.records]
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._cache = {}

    @property
    def records(self) -> Records:
        """Every record in canonical order (one consolidation, cached until the next
        update)."""
        if "records" not in self._cache:
            rec = consolidate(self.parts)
            self.parts = [rec]
            self._cache["records"] = rec
        return self._cache["records"]

    # -- what the records say ----------------------------------------------------------------

    @property
    def images(self) -> int:
        return len(self.records)

    @property
    def n_gt(self) -> int:
        return int(self.records.targets.size)

    @property
    def detections(self) -> int:
        return int(self.records.detections.size)

    @property
    def design_threshold(self) -> float | None:
        """The objects' declared operating threshold (``None``: none, every object
        counts)."""
        return self.threshold if self.thresholded else None

    @property
    def units(self) -> int:
        """Resampling units of the bootstrap: distinct bootstrap keys of the images (the
        images, or the groups plus the images without one)."""
        return int(np.unique(self.records.images["unit"]).size)

    @property
    def km2(self) -> float | None:
        """The images' total area in km², ``None`` unless every image declares one."""
        km2 = self.records.images["km2"]
        total = float(km2.sum()) if km2.size else 0.0
        return total if km2.size and np.isfinite(km2).all() and total > 0 else None

    def resampled(self) -> Resampled:
        """The records as the replicate computation needs them (cached)."""
        if "resampled" not in self._cache:
            self._cache["resampled"] = Resampled.of(self.records, bool(self.by_class))
        return self._cache["resampled"]

    def ap(self) -> np.ndarray:
        """Exact AP at each COCO IoU threshold over every area (NaN without ground truth, or
        for points under an IoU rule); under the distance rule every entry is the AP at the
        distance tolerance. With classes: the mean over the classes with targets."""
        return self.ap_table()[0]

    def ap_table(self) -> np.ndarray:
        """Exact AP ``(A, T)`` per COCO area range (``all``, small, medium, large) and IoU
        threshold, as ``pycocotools`` computes it with no detection cap: per class (the
        mean over the classes with targets in the range) or class-agnostic; NaN where no
        target counts."""
        if "ap_table" in self._cache:
            return self._cache["ap_table"]
        T, A = len(COCO_IOUS), self.ap_areas or 1
        out = np.full((4, T), np.nan)
        if self.ap_kind == "none":
            return out
        rec = self.records
        aps, counted = [], []
        for det_sel, gt_sel in _class_groups(rec.detections, rec.targets, bool(self.by_class)):
            ap, npig = self._group_ap(det_sel, gt_sel, A)
            aps.append(ap)
            counted.append(npig > 0)
        if aps:  # per range, the mean over the classes with targets in it
            n = np.sum(counted, axis=0)
            total = np.where(np.array(counted)[:, :, None], aps, 0.0).sum(axis=0)
            out[:A] = np.where(n[:, None] > 0, total / np.maximum(n, 1)[:, None], np.nan)
        self._cache["ap_table"] = out
        return out

    def _group_ap(
        self, det_sel: np.ndarray, gt_sel: np.ndarray, areas: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """AP ``(areas, T)`` of the detections and targets selected, per area range and IoU
        threshold, and the targets counted in each range ``(areas,)``."""
        T = len(COCO_IOUS)
        d, g = self.records.detections, self.records.targets
        shift = np.arange(areas * T, dtype=np.uint64)[:, None]  # bit a * T + t: range a, IoU t
        lo = np.array([AREA_RANGES[a][0] for a in range(areas)])[:, None]
        hi = np.array([AREA_RANGES[a][1] for a in range(areas)])[:, None]
        inside = (g["coco_area"][None] >= lo) & (g["coco_area"][None] <= hi)  # (A, targets)
        npig = (inside & gt_sel).sum(axis=1)
        tp = ((d["ap_tp"][det_sel][None] >> shift) & np.uint64(1)).astype(np.float64)
        ig = ((d["ap_ig"][det_sel][None] >> shift) & np.uint64(1)).astype(bool)
        ap = coco_ap_rows(tp, (1.0 - tp) * ~ig, np.repeat(npig, T)).reshape(areas, T)
        return ap, npig

    def class_ap(self) -> dict[str, tuple[float, float]]:
        """Per ground-truth class, ``(AP50, AP50:95)`` over every area, as pycocotools
        computes a category's AP; empty unless detections were matched within their class
        and AP is at an IoU."""
        if not self.by_class or self.ap_kind != "iou":
            return {}
        rec = self.records
        d, g = rec.detections, rec.targets
        out = {}
        for c in np.unique(g["label"]):
            ap, npig = self._group_ap(d["label"] == c, g["label"] == c, 1)
            if npig[0] > 0:
                out[str(rec.names[int(c)])] = (float(ap[0, 0]), float(ap[0].mean()))
        return out

    def metrics(self, threshold: float | str | None = "design") -> dict[str, float]:
        """Every object metric at an operating point (``"design"``: the objects' declared
        threshold; a float: detections scoring above it; ``None``: every detection)."""
        thr = self._threshold(threshold)
        key = ("metrics", thr)
        if key not in self._cache:
            self._cache[key] = self._metrics(thr)
        return dict(self._cache[key])

    def _metrics(self, thr: float | None) -> dict[str, float]:
        rec = self.records
        d, g = rec.detections, rec.targets
        sel = above(d["score"], thr)
        tp_ = sel & (d["op"] == TARGET_OP)
        out = ratios(int(tp_.sum()), int((sel & (d["op"] == SCORED)).sum()), self.n_gt, self.images)
        found = above(g["found"], thr) & ~np.isnan(g["found"])
        km2, nan = self.km2, float("nan")
        ap = self.ap()
        out.update(
            fom=out["tp"] / (out["fp"] + self.n_gt) if self.n_gt + out["fp"] else nan,
            fa_per_km2=out["fp"] / km2 if km2 else nan,
            mean_iou=float(d["iou"][tp_].astype(np.float64).sum() / out["tp"])
            if out["tp"]
            else nan,
            fragmentation=float(g["touch"][found].sum() / found.sum()) if found.any() else nan,
            length_score=LengthErrors()
            .add(g["found_length"][found].astype(np.float64), g["length"][found].astype(np.float64))
            .score,
            ap50=float(ap[0]),
            ap50_95=float(np.mean(ap)) if self.ap_kind != "distance" else nan,
        )
        table = self.ap_table()
        for a, size in enumerate(("small", "medium", "large"), start=1):
            out[f"ap_{size}"] = float(np.mean(table[a])) if self.ap_kind == "iou" else nan
        reads = replicate_metrics(self.resampled(), None, thr, self.ap_kind)
        for k in ("pauc", *(f"pd_at_{level:g}_fa_per_image" for level in FA_LEVELS)):
            out[k] = float(reads[k][0])
        return out

    def _threshold(self, threshold: float | str | None) -> float | None:
        if isinstance(threshold, str):
            if threshold != "design":
                raise ValueError(f"threshold must be a number, None or 'design', got {threshold!r}")
            return self.design_threshold
        return None if threshold is None else float(threshold)

    def replicate_metrics(self, threshold: float | str | None = "design") -> dict[str, np.ndarray]:
        """The headline metrics of every bootstrap replicate (``(replicates,)`` each, NaN
        where undefined): ``precision``, ``recall``, ``f1``, ``fom`` and ``fa_per_image`` at
        the operating point, ``ap50``, Pd at each of :data:`FA_LEVELS` false alarms per image
        and ``pauc``."""
        thr = self._threshold(threshold)
        key = ("replicates", thr)
        if key not in self._cache:
            from torchsar.metrics.bootstrap import poisson_weights

            res = self.resampled()
            w = poisson_weights(res.units, self.replicates, self.seed)
            self._cache[key] = replicate_metrics(res, w, thr, self.ap_kind)
        return self._cache[key]

    def intervals(
        self, threshold: float | str | None = "design", level: float = 0.95
    ) -> dict[str, Interval]:
        """Intervals of the headline metrics at an operating point (see
        :func:`~torchsar.metrics.intervals.headline_intervals`)."""
        km2 = self.km2
        per_km2 = self.images / km2 if km2 else None
        return headline_intervals(
            self.metrics(threshold),
            self.replicate_metrics(threshold),
            self.units,
            self.n_gt,
            level,
            per_km2,
        )

    def froc(self) -> dict[str, np.ndarray]:
        """The dense FROC: one point per score level where the counted detections change,
        highest first: ``threshold`` (the level: detections scoring at or above it),
        ``tp``, ``fp``, ``fa_per_image``, ``pd`` (see :mod:`torchsar.metrics.curves`)."""
        d = self.records.detections
        ends = levels(d["score"])
        ct = np.cumsum(d["op"] == TARGET_OP)[ends] if ends.size else np.zeros(0, np.int64)
        cf = np.cumsum(d["op"] == SCORED)[ends] if ends.size else np.zeros(0, np.int64)
        change = np.append(True, (np.diff(ct) != 0) | (np.diff(cf) != 0)) if ends.size else ends
        keep = change & ((ct > 0) | (cf > 0)) if ends.size else change.astype(bool)
        ct, cf, thr = ct[keep], cf[keep], d["score"][ends][keep]
        nan = float("nan")
        return {
            "threshold": thr,
            "tp": ct,
            "fp": cf,
            "fa_per_image": cf / max(self.images, 1),
            "pd": ct / self.n_gt if self.n_gt else np.full(ct.shape, nan),
        }

    def pr_curves(self, iou: int = 0) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
        """``[(class, recall points, precision, score)]`` at COCO IoU threshold index ``iou``
        (area ``all``): COCO's interpolated precision at the recall points reached and the
        score of the detection where each is reached (the curve behind AP). One curve
        ``"all"`` class-agnostic; per class one curve each, then ``"mean"``: their mean
        precision at every recall point (the curve behind the mean AP; no score)."""
        from torchsar.metrics.curves import RECALL_POINTS, interpolated_precision

        rec = self.records
        d, g = rec.detections, rec.targets
        if not self.n_gt or self.ap_kind == "none":
            return []
        out = []
        names = [*rec.names, ""]
        for det_sel, gt_sel in _class_groups(d, g, bool(self.by_class)):
            n_gt = int(gt_sel.sum())
            mine = d[det_sel]
            tp = bit(mine["ap_tp"], iou).astype(np.int64)
            fp = 1 - (tp | bit(mine["ap_ig"], iou))
            tp_cum, fp_cum = np.cumsum(tp), np.cumsum(fp)
            prec, _ = interpolated_precision(tp_cum, fp_cum, n_gt)
            idx = np.searchsorted(tp_cum / n_gt, RECALL_POINTS, side="left")
            ok = idx < mine.size
            label = names[int(g["label"][gt_sel][0])] if self.by_class else "all"
            out.append((label, RECALL_POINTS[ok], prec[ok], mine["score"][idx[ok]], prec))
        if self.by_class and out:
            mean = np.mean([c[4] for c in out], axis=0)
            out.append(("mean", RECALL_POINTS, mean, np.full(RECALL_POINTS.size, np.nan), mean))
        return [c[:4] for c in out]

    def breakdown(self, threshold: float | str | None = "design") -> dict[str, dict]:
        """Counts per breakdown key at an operating point: ``class:NAME`` (targets by class,
        false alarms by the detection's class, else its image's, else
        :data:`NO_CLASS`), ``size:NAME`` (targets by their area, false alarms by theirs),
        ``group:NAME`` and ``image_class:NAME`` (the images of the key); each ``{images,
        n_gt, tp, fp}`` (``images`` 0 for class and size keys)."""
        thr = self._threshold(threshold)
        rec = self.records
        d, g, im = rec.detections, rec.targets, rec.images
        names = np.array([*rec.names, NO_CLASS], dtype=object)
        sel = above(d["score"], thr)
        fa = d["op"] == SCORED
        found = above(g["found"], thr) & ~np.isnan(g["found"])
        img_cls = np.where(im["cls"] >= 0, im["cls"], len(rec.names))
        fa_cls = np.where(d["label"] >= 0, d["label"], img_cls[d["image"]] if d.size else 0)
        sizes = np.array(self.size_names, dtype=object)
        out: dict[str, dict] = {}
        for prefix, gt_key, fa_key in (
            ("class", names[g["label"]], names[fa_cls[fa]]),
            ("size", sizes[g["size"]], sizes[d["size"][fa]]),
        ):
            for k in sorted(set(gt_key.tolist()) | set(fa_key.tolist())):
                mine = gt_key == k
                out[f"{prefix}:{k}"] = {
                    "images": 0,
                    "n_gt": int(mine.sum()),
                    "tp": int((mine & found).sum()),
                    "fp": int((fa_key[sel[fa]] == k).sum()) if fa.any() else 0,
                }
        tp_det = sel & (d["op"] == TARGET_OP)
        for prefix, field_ in (("group", "group"), ("image_class", "cls")):
            for idx in np.unique(im[field_][im[field_] >= 0]):
                planes = im[field_] == idx
                on_d, on_g = planes[d["image"]], planes[g["image"]]
                out[f"{prefix}:{rec.names[idx]}"] = {
                    "images": int(planes.sum()),
                    "n_gt": int(on_g.sum()),
                    "tp": int((on_d & tp_det).sum()),
                    "fp": int((on_d & sel & fa).sum()),
                }
        return out

    def fa_types(self, threshold: float | str | None = "design") -> np.ndarray:
        """False alarms per type (index: :data:`~torchsar.metrics.error_types.FA_TYPES`) at
        an operating point."""
        from torchsar.metrics.error_types import FA_TYPES

        d = self.records.detections
        sel = above(d["score"], self._threshold(threshold)) & (d["fa_type"] != NOT_FA)
        return np.bincount(d["fa_type"][sel], minlength=len(FA_TYPES))[: len(FA_TYPES)]

    def scr_rows(self, threshold: float | str | None = "design", level: float = 0.95) -> list[dict]:
        """Pd per signal-to-clutter ratio bin at an operating point (see
        :func:`torchsar.metrics.scr.scr_rows`)."""
        from torchsar.metrics.scr import scr_rows

        g = self.records.targets
        found = above(g["found"], self._threshold(threshold)) & ~np.isnan(g["found"])
        known = g["scr_known"].astype(np.float64)
        sources = {}
        for source in self.scr_sources:
            if source == "measured":
                sources[source] = (g["scr"].astype(np.float64), found)
            else:
                declared = ~np.isnan(known)
                sources[source] = (known[declared], found[declared])
        return scr_rows(sources, level)

    def choose_threshold(self, kind: str, level: float | None = None) -> float | None:
        """The operating threshold a calibration split picks (at a detection score: the
        highest score left out, ``None`` when every detection is kept): ``kind="fa"``, the
        most detections with at most ``level`` false alarms per image; ``kind="f1"``, the
        best F1 (ties: the fewer detections)."""
        d = self.records.detections
        ends = levels(d["score"])
        ct = np.concatenate([[0], np.cumsum(d["op"] == TARGET_OP)[ends]]) if ends.size else [0]
        cf = np.concatenate([[0], np.cumsum(d["op"] == SCORED)[ends]]) if ends.size else [0]
        ct, cf = np.asarray(ct, np.float64), np.asarray(cf, np.float64)
        if kind == "fa":
            ok = np.flatnonzero(cf / max(self.images, 1) <= level)
            k = int(ok[-1]) if ok.size else 0
        else:
            f1 = np.array(
                [
                    ratios(int(t), int(f), self.n_gt, self.images)["f1"]
                    for t, f in zip(ct, cf, strict=True)
                ]
            )
            f1 = np.nan_to_num(f1, nan=-1.0)
            k = int(np.flatnonzero(f1 == f1.max())[0])
        if k == ends.size:
            return None
        return float(d["score"][ends[k]])


AREA_RANGES = ((0.0, 1e10), (0.0, 32.0**2), (32.0**2, 96.0**2), (96.0**2, 1e10))
"""COCO's area ranges of AP (``all``, small, medium, large; bounds inclusive)."""


def _class_groups(d: np.ndarray, g: np.ndarray, by_class: bool) -> list:
    """``(detections, targets)`` selections of each class (one group, class-agnostic)."""
    if not by_class:
        return [(np.ones(d.size, bool), np.ones(g.size, bool))]
    return [(d["label"] == c, g["label"] == c) for c in np.unique(g["label"])]


def _sources(sources: set[str]) -> tuple[str, ...]:
    """SCR sources in table order: ``measured`` first."""
    return tuple(sorted(sources, key=lambda s: (s != "measured", s)))
