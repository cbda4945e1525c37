"""Additive object-level scoring state: fixed-size histograms that merge by addition.

One :class:`ObjectState` per detector and dataset holds, over a fixed score grid
(:data:`~torchsar.metrics.curves.SCORE_GRID`):

- one record per detection with its status at the ten COCO IoU thresholds, ranked once at
  the end for exact AP50 and AP50:95 on scores of any range
  (:class:`~torchsar.metrics.ranked.RankedDetections`, 24 bytes per detection);
- TP / FP histograms and the summed IoU of matches under the matching rule (operating point,
  precision / recall / F1, FoM, FROC, Pd at fixed false alarms per image);
- the same TP / FP histograms per breakdown key: ground-truth class (false alarms go to the
  image's class when it has one), size bin (instances by their area, false alarms by theirs)
  and image group (e.g. the clutter model of a simulated image);
- Poisson-bootstrap replicates of the rule's and the IoU-0.5 histograms (see
  :mod:`torchsar.metrics.bootstrap`) for intervals over images.

Histograms bin each detection's score normalised by its detector's operating threshold
(:func:`normalise`), so the operating point is score bin :data:`OP_BIN` for every detector;
objects without a declared threshold are binned by their raw score and every one of them
counts at the operating point. Only the AP records grow with the number of detections, and
any split of a dataset into batches, shards or workers gives identical states once added up.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from torchsar.metrics.assign import BatchMatch
from torchsar.metrics.bootstrap import poisson_weights
from torchsar.metrics.curves import (
    OP_BIN,
    SCORE_GRID,
    coco_ap_rows,
    froc,
    partial_auc,
    partial_auc_rows,
    pd_at_fa,
    score_bins,
    suffix,
)
from torchsar.metrics.distance import LengthErrors
from torchsar.metrics.intervals import Interval, headline_intervals
from torchsar.metrics.matching import COCO_IOUS, GroundTruth
from torchsar.metrics.ranked import RankedDetections, plane_ranks
from torchsar.objects import Objects

__all__ = [
    "FA_LEVELS",
    "ImageInfo",
    "KeyCounts",
    "ObjectState",
    "normalise",
    "operating_point",
    "size_bin",
]

N_BINS = SCORE_GRID.size + 1
FA_LEVELS = (0.1, 1.0, 10.0)
NO_CLASS = "(no image class)"


@dataclass(frozen=True)
class ImageInfo:
    """What the scorer needs to know about one plane beyond its pixels."""

    key: str
    cls: str | None = None
    group: str | None = None
    km2: float | None = None
    order: int | None = None
    """Global order of the plane in its dataset (ties in score are ranked by it, as
    ``pycocotools`` ranks them by image id); default: its position in the batch."""
    boot_key: str | None = None
    """The bootstrap's resampling unit of the plane (planes with the same ``boot_key`` get the
    same replicate weights, e.g. the images of one scene); default: ``key``."""


def normalise(score: np.ndarray, threshold: float | None) -> np.ndarray:
    """Scores relative to the operating ``threshold``: ``score / threshold`` (threshold >
    0), else ``1 + score - threshold``, so the threshold maps to 1; ``None``: unchanged.

    Example:
        >>> normalise(np.array([0.25, 0.5, 1.0]), 0.5).tolist()
        [0.5, 1.0, 2.0]
    """
    s = np.asarray(score, dtype=np.float64)
    if threshold is None:
        return s
    return s / threshold if threshold > 0 else 1.0 + s - threshold


def size_bin(area: np.ndarray, edges: tuple[float, ...]) -> np.ndarray:
    """Size bin index of each area: bin ``i`` is ``[edges[i-1], edges[i])`` (half-open)."""
    return np.searchsorted(np.asarray(edges, dtype=np.float64), area, side="right")


IOU_UNIT = 10**9
"""IoUs are summed as integers in units of 1e-9, so sums are exact whatever the order."""


def _hist(bins: np.ndarray) -> np.ndarray:
    return np.bincount(bins, minlength=N_BINS)


def _iou_units(bins: np.ndarray, iou: np.ndarray) -> np.ndarray:
    out = np.zeros(N_BINS, np.int64)
    np.add.at(out, bins, np.rint(iou * IOU_UNIT).astype(np.int64))
    return out


def _add_weighted(out: np.ndarray, w: np.ndarray, plane: np.ndarray, bins: np.ndarray) -> None:
    """``out[r, bins[i]] += w[r, plane[i]]`` for every object ``i``, as one integer product
    ``w @ counts`` over the bins present (``counts``: objects per plane and bin; ``w``
    int64)."""
    if bins.size == 0:
        return
    cols, at = np.unique(bins, return_inverse=True)
    n = w.shape[1]
    counts = np.bincount(at * n + plane, minlength=cols.size * n).reshape(cols.size, n)
    out[:, cols] += w @ counts.T


def _planes_by_key(info: list[ImageInfo]) -> dict[str, np.ndarray]:
    """The planes (a bool mask) of each image-level key, ``group:`` and ``image_class:``,
    in order of first appearance."""
    out: dict[str, np.ndarray] = {}
    for p, i in enumerate(info):
        for key in (f"group:{i.group}" if i.group else None,
                    f"image_class:{i.cls}" if i.cls else None):  # fmt: skip
            if key is not None:
                out.setdefault(key, np.zeros(len(info), bool))[p] = True
    return out


@dataclass(eq=False)
class KeyCounts:
    """Per breakdown key: instances, images and TP / FP score histograms (additive)."""

    n_gt: int = 0
    images: int = 0
    tp: np.ndarray = field(default_factory=lambda: np.zeros(N_BINS, np.int64))
    fp: np.ndarray = field(default_factory=lambda: np.zeros(N_BINS, np.int64))

    def __add__(self, other: KeyCounts) -> KeyCounts:
        return KeyCounts(
            self.n_gt + other.n_gt, self.images + other.images,
            self.tp + other.tp, self.fp + other.fp,
        )  # fmt: skip


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
    images: int = 0
    area_mm2: int = 0
    images_km2: int = 0
    n_gt: int = 0
    ranked: RankedDetections = field(default_factory=lambda: RankedDetections(len(COCO_IOUS)))
    thresholded: bool | None = None
    ap_kind: str | None = None
    threshold: float | None = None
    tp: np.ndarray = field(default_factory=lambda: np.zeros(N_BINS, np.int64))
    fp: np.ndarray = field(default_factory=lambda: np.zeros(N_BINS, np.int64))
    iou_sum: np.ndarray = field(default_factory=lambda: np.zeros(N_BINS, np.int64))
    fragments: int = 0
    fragmented: int = 0
    lengths: LengthErrors = field(default_factory=LengthErrors)
    keys: dict[str, KeyCounts] = field(default_factory=dict)
    boot: dict[str, np.ndarray] = field(default_factory=dict)
    grouped: bool = False
    """Whether some planes were resampled by a group key (:attr:`ImageInfo.boot_key`)."""

    def __post_init__(self) -> None:
        if len(self.size_names) != len(self.size_edges) + 1:
            raise ValueError("size_names needs one name more than size_edges")
        if not self.boot:
            r = self.replicates
            self.boot = {k: np.zeros((r, N_BINS), np.int64) for k in ("tp", "fp", "tp50", "fp50")}
            self.boot["n_gt"] = np.zeros(r, np.int64)
            self.boot["images"] = np.zeros(r, np.int64)

    # -- accumulation ------------------------------------------------------------------------

    def update(self, m: BatchMatch, obj: Objects, gt: GroundTruth, info: list[ImageInfo]) -> None:
        """Add one matched batch (``info``: one entry per plane)."""
        bins = score_bins(normalise(obj.score, obj.threshold))
        hit, false = m.op >= 0, m.op == -1
        self.images += len(info)
        spaced = [i.km2 for i in info if i.km2 is not None]
        self.area_mm2 += sum(round(a * 1e12) for a in spaced)  # integers: exact in any order
        self.images_km2 += len(spaced)
        self.n_gt += len(gt)
        self._update_ranked(m, obj, info)
        self.tp += _hist(bins[hit])
        self.fp += _hist(bins[false])
        self.iou_sum += _iou_units(bins[hit], m.op_iou[hit])
        gt_bins = np.where(m.gt_det >= 0, bins[np.maximum(m.gt_det, 0)] if bins.size else 0, -1)
        found = gt_bins >= OP_BIN if obj.threshold is not None else gt_bins >= 0
        self.fragments += int(m.overlaps[found].sum())
        self.fragmented += int(found.sum())
        self._update_lengths(m, obj, gt, bins)
        self._update_keys(m, obj, gt, info, bins, gt_bins)
        if self.replicates:
            self._update_boot(m, obj, gt, info, bins)

    def _update_lengths(self, m: BatchMatch, obj: Objects, gt: GroundTruth, bins) -> None:
        """Length errors of the matches at the design operating point where both the
        detection and its instance declare a length in metres."""
        if obj.length_m is None or gt.length_m is None:
            return
        at = bins >= (OP_BIN if obj.threshold is not None else 0)
        hit = np.flatnonzero(at & (m.op >= 0))
        self.lengths = self.lengths.add(obj.length_m[hit], gt.length_m[m.op[hit]])

    def _update_ranked(self, m: BatchMatch, obj: Objects, info: list[ImageInfo]) -> None:
        """The AP records, and what the objects say about their operating point and AP."""
        if len(obj):
            declared = obj.threshold is not None
            if self.thresholded is not None and (self.thresholded, self.threshold) != (
                    declared, obj.threshold):  # fmt: skip
                raise ValueError("objects with different operating thresholds in one state")
            self.thresholded, self.threshold = declared, obj.threshold
            if self.ap_kind is not None and m.ap_kind != self.ap_kind:
                raise ValueError(f"AP of kinds {self.ap_kind} and {m.ap_kind} in one state")
            self.ap_kind = m.ap_kind
        order = np.array([p if i.order is None else i.order for p, i in enumerate(info)],
                         dtype=np.int64)  # fmt: skip
        image = order[obj.plane] if len(obj) else np.zeros(0, np.int64)
        self.ranked.update(obj.score, image, m.ap, plane_ranks(obj.plane))

    @property
    def op_bin(self) -> int:
        """The design operating point: scores above the declared threshold (bin
        :data:`OP_BIN`), or every object when the objects declared none (bin 0)."""
        return 0 if self.thresholded is False else OP_BIN

    def _add_key(self, key: str, **parts) -> None:
        self.keys[key] = self.keys.get(key, KeyCounts()) + KeyCounts(**parts)

    def _update_keys(self, m, obj, gt, info, bins, gt_bins) -> None:
        false = m.op == -1
        image_cls = np.array([i.cls or NO_CLASS for i in info], dtype=object)
        fp_size = self._size_names(obj.area[false])
        groups = [
            ("class", gt.classes, image_cls[obj.plane[false]]),
            ("size", self._size_names(gt.area), fp_size),
        ]
        for prefix, gt_keys, fp_keys in groups:
            for k in set(gt_keys.tolist()) | set(fp_keys.tolist()):
                mine = gt_keys == k
                self._add_key(
                    f"{prefix}:{k}", n_gt=int(mine.sum()),
                    tp=_hist(gt_bins[mine & (gt_bins >= 0)]),
                    fp=_hist(bins[false][fp_keys == k]),
                )  # fmt: skip
        for key, planes in _planes_by_key(info).items():
            d, g = planes[obj.plane], planes[gt.plane]
            self._add_key(
                key, n_gt=int(g.sum()), images=int(planes.sum()),
                tp=_hist(bins[d & (m.op >= 0)]), fp=_hist(bins[d & false]),
            )  # fmt: skip

    def _size_names(self, area: np.ndarray) -> np.ndarray:
        names = np.array(self.size_names, dtype=object)
        return names[size_bin(area, self.size_edges)]

    def _update_boot(self, m, obj, gt, info, bins) -> None:
        self.grouped = self.grouped or any(i.boot_key for i in info)
        w = poisson_weights([i.boot_key or i.key for i in info], self.replicates, self.seed)
        w = w.astype(np.int64)  # once for the four histograms (integer sums: exact)
        for name, sel in (("tp", m.op >= 0), ("fp", m.op == -1),
                          ("tp50", m.ap[0] >= 0), ("fp50", m.ap[0] == -1)):  # fmt: skip
            _add_weighted(self.boot[name], w, obj.plane[sel], bins[sel])
        per_plane = np.bincount(gt.plane, minlength=len(info))
        self.boot["n_gt"] += w @ per_plane
        self.boot["images"] += w.sum(axis=1)

    # -- merging -----------------------------------------------------------------------------

    def __add__(self, other: ObjectState) -> ObjectState:
        same = (self.replicates, self.seed, self.size_edges, self.size_names)
        if same != (other.replicates, other.seed, other.size_edges, other.size_names):
            raise ValueError("cannot add ObjectStates with different settings")
        keys = dict(self.keys)
        for k, v in other.keys.items():
            keys[k] = keys.get(k, KeyCounts()) + v
        if None not in (self.thresholded, other.thresholded) and (
                self.threshold != other.threshold):  # fmt: skip
            raise ValueError("cannot add states with different operating thresholds")
        declared = other.thresholded if self.thresholded is None else self.thresholded
        threshold = other.threshold if self.thresholded is None else self.threshold
        if None not in (self.ap_kind, other.ap_kind) and self.ap_kind != other.ap_kind:
            raise ValueError("cannot add states of different AP kinds")
        kind = other.ap_kind if self.ap_kind is None else self.ap_kind
        summed = {
            k: getattr(self, k) + getattr(other, k)
            for k in ("images", "area_mm2", "images_km2", "n_gt", "ranked", "tp", "fp",
                      "iou_sum", "fragments", "fragmented", "lengths")
        }  # fmt: skip
        return ObjectState(
            replicates=self.replicates, seed=self.seed, size_edges=self.size_edges,
            size_names=self.size_names, thresholded=declared, ap_kind=kind,
            threshold=threshold, keys=keys, grouped=self.grouped or other.grouped,
            boot={k: self.boot[k] + other.boot[k] for k in self.boot}, **summed,
        )  # fmt: skip

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ObjectState):
            return NotImplemented
        return _same(self.__dict__, other.__dict__)

    # -- results -----------------------------------------------------------------------------

    def metrics(self, at: int | None = None) -> dict[str, float]:
        """Every object metric with the operating point at score bin ``at`` (default: the
        design point :attr:`op_bin`). AP is exact (from the per-detection records)."""
        at = self.op_bin if at is None else at
        ap = self.ap()
        out = operating_point(self.tp, self.fp, self.n_gt, self.images, at)
        tp = out["tp"]
        fa, pd = froc(self.tp, self.fp, self.n_gt, self.images)
        km2 = self.area_mm2 / 1e12
        full = self.images_km2 == self.images and km2 > 0
        out.update(
            fom=tp / (out["fp"] + self.n_gt) if self.n_gt + out["fp"] else float("nan"),
            fa_per_km2=out["fp"] / km2 if full else float("nan"),
            mean_iou=float(self.iou_sum[at:].sum() / IOU_UNIT / tp) if tp else float("nan"),
            fragmentation=self.fragments / self.fragmented if self.fragmented else float("nan"),
            length_score=self.lengths.score,
            ap50=float(ap[0]),
            ap50_95=float(np.mean(ap)) if self.ap_kind != "distance" else float("nan"),
            pauc=partial_auc(fa, pd, 1.0) if self.n_gt else float("nan"),
        )  # fmt: skip
        for level in FA_LEVELS:
            out[f"pd_at_{level:g}_fa_per_image"] = (
                pd_at_fa(fa, pd, level) if self.n_gt else float("nan")
            )
        return out

    def ap(self) -> np.ndarray:
        """Exact AP at each COCO IoU threshold (NaN without ground truth, or for points
        under an IoU rule); under the distance rule every entry is the AP at the distance
        tolerance."""
        if self.ap_kind == "none":
            return np.full(len(COCO_IOUS), np.nan)
        return self.ranked.ap(self.n_gt)

    @property
    def units(self) -> int:
        """Resampling units of the bootstrap: the images, or (planes resampled by group)
        the groups plus the images without one."""
        if not self.grouped:
            return self.images
        groups = [k for name, k in self.keys.items() if name.startswith("group:")]
        return len(groups) + self.images - sum(k.images for k in groups)

    def intervals(self, at: int | None = None, level: float = 0.95) -> dict[str, Interval]:
        """Intervals of the headline metrics at score bin ``at`` (see
        :func:`~torchsar.metrics.intervals.headline_intervals`)."""
        km2 = self.area_mm2 / 1e12
        per_km2 = self.images / km2 if self.images_km2 == self.images and km2 > 0 else None
        return headline_intervals(self.metrics(at), self.replicate_metrics(at), self.units,
                                  self.n_gt, level, per_km2)  # fmt: skip

    def replicate_metrics(self, at: int | None = None) -> dict[str, np.ndarray]:
        """The headline metrics of every bootstrap replicate (``(replicates,)`` each, NaN
        where undefined): ``precision``, ``recall``, ``f1``, ``fom`` and
        ``fa_per_image`` at score bin ``at``, ``ap50``, Pd at each of :data:`FA_LEVELS`
        false alarms per image and ``pauc``."""
        at = self.op_bin if at is None else at
        b, nan = self.boot, float("nan")
        n_gt, images = b["n_gt"].astype(np.float64), b["images"].astype(np.float64)
        t, f = b["tp"][:, at:].sum(axis=1), b["fp"][:, at:].sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            reps = {
                "precision": np.where(t + f > 0, t / (t + f), nan),
                "recall": np.where(n_gt > 0, t / n_gt, nan),
                "f1": np.where(t + f + n_gt > 0, 2 * t / (2 * t + f + (n_gt - t)), nan),
                "fom": np.where(f + n_gt > 0, t / (f + n_gt), nan),
                "fa_per_image": np.where(images > 0, f / images, nan),
            }
            zero = np.zeros((n_gt.size, 1))
            fa = np.hstack([zero, suffix(b["fp"])[:, ::-1]]) / np.maximum(images, 1)[:, None]
            pd = np.hstack([zero, suffix(b["tp"])[:, ::-1]]) / n_gt[:, None]
        reps["ap50"] = (coco_ap_rows(b["tp50"], b["fp50"], n_gt) if self.ap_kind != "none"
                        else np.full(n_gt.size, nan))  # fmt: skip
        for level in FA_LEVELS:
            best = np.where(fa <= level, pd, 0.0).max(axis=1, initial=0.0)
            reps[f"pd_at_{level:g}_fa_per_image"] = np.where(n_gt > 0, best, nan)
        reps["pauc"] = np.where(n_gt > 0, partial_auc_rows(fa, pd, 1.0), nan)
        return reps

    def score_at(self, at: int) -> float:
        """The threshold, on the objects' own score scale, of an operating point starting at
        score bin ``at`` (scores above it count)."""
        level = float(SCORE_GRID[at - 1]) if at > 0 else float("-inf")
        t = self.threshold
        if t is None or not np.isfinite(level):
            return level
        return level * t if t > 0 else level - 1.0 + t

    def froc(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(score threshold, false alarms per image, Pd)``, highest threshold first."""
        fa, pd = froc(self.tp, self.fp, self.n_gt, self.images)
        thr = np.concatenate([[np.inf], SCORE_GRID[::-1], [-np.inf]])
        return thr[: fa.size], fa, pd


def _same(a: object, b: object) -> bool:
    """Deep equality of states (arrays, dicts, dataclasses, scalars)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(a, b)
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, KeyCounts) and isinstance(b, KeyCounts):
        return _same(a.__dict__, b.__dict__)
    return a == b


def operating_point(tp: np.ndarray, fp: np.ndarray, n_gt: int, images: int, at: int) -> dict:
    """TP, FP, FN, precision, recall, F1 and false alarms per image of the detections in
    score bins ``>= at``."""
    t, f = int(tp[at:].sum()), int(fp[at:].sum())
    nan = float("nan")
    return {
        "tp": t,
        "fp": f,
        "fn": n_gt - t,
        "precision": t / (t + f) if t + f else nan,
        "recall": t / n_gt if n_gt else nan,
        "f1": 2 * t / (2 * t + f + (n_gt - t)) if (t + f + n_gt) else nan,
        "fa_per_image": f / images if images else nan,
    }
