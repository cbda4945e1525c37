"""pycocotools' ``COCOeval`` (``evaluate``, ``accumulate``, ``summarize``) as an additive,
mergeable state that reproduces the 12 numbers of ``COCOeval.stats`` exactly.

The caller computes the IoU matrices (mask or box IoU, with COCO's crowd rule) and hands in
one :class:`CocoImage` per image; :class:`CocoState` does the rest, as ``COCOeval`` does with
``iouType`` ``"segm"`` or ``"bbox"``, ``useCats=1`` and default parameters.

What the state keeps:

- one record per kept detection (the first ``max_dets[-1]`` of each image and category, by
  score): score, category, image order, rank within its image and category, and for every
  (area range, IoU threshold) two bits, true positive and false positive (neither: ignored);
- per category and area range, the non-ignored ground-truth count (``npig``);
- the orders of the images added (8 bytes per image), so that overlapping shards are refused.

Cost per detection: 22 bytes plus ``ceil(2 * A * T / 8)`` bytes of bits, 32 bytes with the
COCO defaults (4 area ranges, 10 IoU thresholds).

The matching of ``evaluateImg`` only looks at one image and category, so it is final once the
image is added. ``accumulate`` ranks the detections of all images at once (score descending,
ties by image order then by rank in the image), which is one sort of the merged records; so a
merge is a concatenation of records plus a sum of counts, and any split of the images into
updates, merged with ``+`` in any order, gives equal states and identical stats.

pycocotools' rules reproduced literally:

- per (image, category, area range): ground truth outside the area range (``area < lo`` or
  ``area > hi``, bounds inclusive) or crowd is ignored and sorted last (stable); detections
  sorted by descending score (stable: file order breaks ties) and cut to ``max_dets[-1]``;
- the greedy loop per IoU threshold: a detection takes, among the ground truth not yet matched
  (crowd can be matched again) with IoU at least ``min(t, 1 - 1e-10)``, the one of highest
  IoU (ties: the later one), looking at the ignored ones only when no non-ignored one
  qualifies; a matched detection inherits the instance's ignore flag; an unmatched detection
  outside the area range is ignored;
- ``accumulate``: per category, area range and ``maxDet``, the first ``maxDet`` detections of
  each image, ranked together (stable, image order then rank); precision and recall from
  :func:`~torchsar.metrics.curves.interpolated_precision`; -1 where ``npig`` is 0;
- ``summarize``: means over entries > -1 (-1 when none), the first stat at ``maxDets=100``.

Conventions where pycocotools' inputs differ from these:

- Categories: pycocotools uses the ground-truth file's category list; here the categories seen
  in ground truth or detections. A category without non-ignored ground truth gives -1 entries,
  which the means leave out, so the stats are the same; ``precision`` / ``recall`` have one
  ``K`` slot per category seen (those of an unseen listed category would be all -1).
  pycocotools drops detections of a category missing from its list; such a category has no
  ground truth, so its -1 entries here change nothing either.
- IoU thresholds: pycocotools' ``np.linspace(0.5, 0.95, 10)``
  (:data:`~torchsar.metrics.matching.COCO_IOUS`), not rounded: its 0.9 is
  0.8999999999999999, and a rounded 0.9 would refuse an IoU of exactly that value.
- pycocotools counts a match to a ground-truth instance of id 0 as no match (``dtMatches``
  holds ids, 0 meaning none); COCO ids start at 1, and the ids play no part here.
- A ground-truth ``ignore`` key has no effect in pycocotools (``_prepare`` overwrites it with
  ``iscrowd``), nor here.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from torchsar.errors import InputValueError, OptionError, ShapeError
from torchsar.metrics.curves import RECALL_POINTS, interpolated_precision
from torchsar.metrics.matching import COCO_IOUS

__all__ = [
    "COCO_AREAS",
    "COCO_MAX_DETS",
    "CocoImage",
    "CocoState",
    "greedy_coco_match",
    "summarize",
]

COCO_AREAS: dict[str, tuple[float, float]] = {
    "all": (0.0, 1e10),
    "small": (0.0, 32.0**2),
    "medium": (32.0**2, 96.0**2),
    "large": (96.0**2, 1e10),
}
"""pycocotools' area ranges (``Params.areaRng``, bounds inclusive) by label."""

COCO_MAX_DETS = (1, 10, 100)
"""pycocotools' detection caps per image and category (``Params.maxDets``)."""

"""pycocotools' IoU thresholds (``Params.iouThrs``, unrounded; see the module docstring)."""

_WORK = 1 << 22
"""Elements of the matcher's arrays per batch of problems (see ``_batches``)."""


@dataclass(frozen=True)
class CocoImage:
    """One image's inputs, as pycocotools sees them.

    Attributes:
        order: the image's rank in pycocotools' sorted image-id order (distinct per image; ties
            between detections of different images are broken by it).
        gt_category: ``(G,)`` int64 category of each ground-truth instance, annotation order.
        gt_area: ``(G,)`` float64 annotation ``area`` (used for the area ranges).
        gt_crowd: ``(G,)`` bool ``iscrowd``.
        det_category: ``(D,)`` int64, detections in results-file order (pycocotools breaks
            score ties within an image by this order).
        det_score: ``(D,)`` float64 score.
        det_area: ``(D,)`` float64 area (pycocotools: the mask area for ``segm``, ``w * h`` for
            ``bbox``).
        iou: ``(D, G)`` float64 IoU of detection ``d`` with instance ``g`` exactly as
            ``pycocotools.mask.iou`` gives it (for a crowd instance: intersection over the
            detection's area). Only pairs of the same category are used.

    Examples:
        >>> im = CocoImage(0, [1], [500.0], [False], [1], [0.9], [480.0], [[0.8]])
        >>> im.iou.shape, im.gt_crowd.dtype
        ((1, 1), dtype('bool'))
    """

    order: int
    gt_category: np.ndarray
    gt_area: np.ndarray
    gt_crowd: np.ndarray
    det_category: np.ndarray
    det_score: np.ndarray
    det_area: np.ndarray
    iou: np.ndarray

    def __post_init__(self) -> None:
        typed = {
            "gt_category": np.int64,
            "gt_area": np.float64,
            "gt_crowd": bool,
            "det_category": np.int64,
            "det_score": np.float64,
            "det_area": np.float64,
        }
        for name, dtype in typed.items():
            a = np.asarray(getattr(self, name))
            if a.ndim != 1:
                raise ShapeError(f"{name} must be 1-D, got shape {a.shape}")
            object.__setattr__(self, name, a.astype(dtype, copy=False))
        g, d = self.gt_category.size, self.det_category.size
        for name, n in (("gt_area", g), ("gt_crowd", g), ("det_score", d), ("det_area", d)):
            if getattr(self, name).size != n:
                raise ShapeError(f"{name} has {getattr(self, name).size} entries, expected {n}")
        iou = np.asarray(self.iou, dtype=np.float64)
        if iou.size == 0:
            iou = iou.reshape(d, g)
        if iou.shape != (d, g):
            raise ShapeError(
                f"iou must have shape {(d, g)} (detections, instances), got {iou.shape}"
            )
        if np.isnan(iou).any() or np.isnan(self.det_score).any():
            raise InputValueError("iou and det_score must not be NaN")
        if not -(2**31) <= int(self.order) < 2**31:
            raise OptionError(f"order must fit in int32, got {self.order}")
        object.__setattr__(self, "iou", iou)


def greedy_coco_match(
    iou: np.ndarray, ignore: np.ndarray, crowd: np.ndarray, n_det: np.ndarray, thresholds
) -> tuple[np.ndarray, np.ndarray]:
    """pycocotools' greedy matching (``evaluateImg``) of many problems at once.

    One problem is one (image, category); detections are in ranked order, instances in
    annotation order (padding columns have IoU ``-inf``). Per area range and threshold, each
    detection in turn takes the instance of highest IoU (ties: the later one) among those not
    yet matched (crowd ones can be matched again) with IoU at least ``min(t, 1 - 1e-10)``,
    non-ignored instances first: the ignored ones only when no non-ignored one qualifies.

    Args:
        iou: ``(P, D, G)`` IoU of each problem's detection ``d`` with its instance ``g``.
        ignore: ``(P, A, G)`` ignored instances per area range (crowd or outside the range).
        crowd: ``(P, G)`` crowd instances.
        n_det: ``(P,)`` detections of each problem, non-increasing (rows past it are padding).
        thresholds: ``(T,)`` IoU thresholds.

    Returns:
        ``(matched, matched_ignored)``, each ``(P, D, A, T)`` bool.

    Examples:
        >>> iou = np.array([[[0.6, 0.6], [0.7, 0.0]]])  # two detections, two instances
        >>> m, ig = greedy_coco_match(iou, np.zeros((1, 1, 2), bool), np.zeros((1, 2), bool),
        ...                           np.array([2]), [0.5, 0.65])
        >>> m[0, :, 0].tolist()  # per detection, at 0.5 and 0.65: the first only reaches 0.6
        [[True, False], [True, True]]
    """
    P, D, G = iou.shape
    A, thr = ignore.shape[1], np.minimum(np.asarray(thresholds, np.float64), 1 - 1e-10)
    matched = np.zeros((P, D, A, thr.size), bool)
    matched_ig = np.zeros((P, D, A, thr.size), bool)
    if P == 0 or D == 0 or G == 0:
        return matched, matched_ig
    rank = _row_ranks(iou)
    # instances first (G, P, ...) so that every step is elementwise over whole arrays; the key
    # 1 + group * G + rank (0: not a candidate) is largest for pycocotools' choice and unique
    iou_t, rank_t = iou.transpose(1, 2, 0).copy(), rank.transpose(1, 2, 0).copy()  # (D, G, P)
    group = np.where(ignore, 1, G + 1).astype(rank.dtype).transpose(2, 0, 1)  # (G, P, A)
    real = ~crowd.T[:, :, None, None]  # (G, P, 1, 1): matched once only
    free = np.ones((G, P, A, thr.size), bool)
    n_det = np.asarray(n_det)
    for d in range(int(n_det.max(initial=0))):
        n = int(np.count_nonzero(n_det > d))  # the active problems are a prefix
        ok = free[:, :n] & (iou_t[d, :, :n, None] >= thr)[:, :, None, :]
        key = (group[:, :n] + rank_t[d, :, :n, None])[..., None] * ok
        best = key.max(0)  # (n, A, T)
        matched[:n, d] = best > 0
        matched_ig[:n, d] = (best > 0) & (best <= G)
        free[:, :n] &= ~((key == best) & (best > 0) & real[:, :n])
    return matched, matched_ig


def _row_ranks(iou: np.ndarray) -> np.ndarray:
    """Rank of each entry within its last-axis row, ascending by value then by position.

    Examples:
        >>> _row_ranks(np.array([[0.5, 0.2, 0.5]])).tolist()
        [[1, 0, 2]]
    """
    order = np.argsort(iou, axis=-1, kind="stable")
    rank = np.empty(iou.shape, np.int16 if 2 * iou.shape[-1] < 2**15 else np.int32)
    np.put_along_axis(rank, order, np.arange(iou.shape[-1], dtype=rank.dtype), axis=-1)
    return rank


def _within(sizes: np.ndarray) -> np.ndarray:
    """Position of each element within its run, runs of ``sizes`` laid end to end.

    Examples:
        >>> _within(np.array([2, 3])).tolist()
        [0, 1, 0, 1, 2]
    """
    return np.arange(int(sizes.sum())) - np.repeat(np.cumsum(sizes) - sizes, sizes)


def _runs(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distinct values of sorted ``keys`` with the start and length of each run.

    Examples:
        >>> [a.tolist() for a in _runs(np.array([3, 3, 5]))]
        [[3, 5], [0, 2], [2, 1]]
    """
    values, starts, sizes = np.unique(keys, return_index=True, return_counts=True)
    return values, starts, sizes


def _outside(area: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """``(N, A)``: area outside each range, pycocotools' ``area < lo or area > hi``.

    Examples:
        >>> _outside(np.array([1024.0]), np.array([[0, 1024], [1024, 9216]])).tolist()
        [[False, False]]
    """
    return (area[:, None] < ranges[:, 0]) | (area[:, None] > ranges[:, 1])


def summarize(
    precision: np.ndarray,
    recall: np.ndarray,
    thresholds: np.ndarray,
    labels: list[str],
    max_dets: tuple[int, ...],
) -> np.ndarray:
    """``COCOeval.summarize`` for ``segm`` / ``bbox``: the 12 stats, literally.

    Args:
        precision: ``(T, R, K, A, M)``, -1 where undefined.
        recall: ``(T, K, A, M)``.
        thresholds: ``(T,)`` IoU thresholds (stats 1 and 2 read 0.5 and 0.75).
        labels: the ``A`` area-range labels (``"all"``, ``"small"``, ...).
        max_dets: the ``M`` sorted caps (at least 3; stat 0 reads 100).

    Returns:
        ``(12,)`` AP, AP50, AP75, AP small / medium / large, AR at the three caps, AR small /
        medium / large (each -1 when nothing is defined).

    Examples:
        >>> p, r = np.ones((10, 101, 1, 4, 3)), np.full((10, 1, 4, 3), 0.5)
        >>> summarize(p, r, COCO_IOUS, list(COCO_AREAS), (1, 10, 100))[[0, 6]].tolist()
        [1.0, 0.5]
    """
    if len(max_dets) < 3:
        raise OptionError(f"summarize needs 3 max_dets as pycocotools, got {max_dets}")

    def one(ap: bool, iou: float | None = None, area: str = "all", cap: int = 100) -> float:
        aind = [i for i, lbl in enumerate(labels) if lbl == area]
        mind = [i for i, m in enumerate(max_dets) if m == cap]
        s = precision if ap else recall
        if iou is not None:
            s = s[np.where(iou == thresholds)[0]]
        s = s[:, :, :, aind, mind] if ap else s[:, :, aind, mind]
        return -1.0 if s[s > -1].size == 0 else float(np.mean(s[s > -1]))

    m0, m1, m2 = max_dets[:3]
    return np.array(
        [
            one(True),
            one(True, 0.5, cap=m2),
            one(True, 0.75, cap=m2),
            one(True, area="small", cap=m2),
            one(True, area="medium", cap=m2),
            one(True, area="large", cap=m2),
            one(False, cap=m0),
            one(False, cap=m1),
            one(False, cap=m2),
            one(False, area="small", cap=m2),
            one(False, area="medium", cap=m2),
            one(False, area="large", cap=m2),
        ]
    )


class CocoState:
    """pycocotools' ``COCOeval`` as an additive state (see the module docstring).

    Args:
        max_dets: detection caps per image and category (sorted, as pycocotools).
        areas: area ranges ``{label: (lo, hi)}``, bounds inclusive.
        iou_thresholds: IoU thresholds (default pycocotools' own, :data:`COCO_IOUS`).

    Examples:
        >>> s = CocoState()
        >>> s.update([CocoImage(0, [1], [500.0], [False], [1], [0.9], [480.0], [[0.8]])])
        >>> s.stats()[[0, 1, 2, 3, 4]].round(3).tolist()  # matched at 0.5 ... 0.8: 7 of 10
        [0.7, 1.0, 1.0, 0.7, -1.0]
        >>> s.categories
        [1]
    """

    __hash__ = None  # mutable

    def __init__(
        self,
        *,
        max_dets: Iterable[int] = COCO_MAX_DETS,
        areas: dict[str, tuple[float, float]] = COCO_AREAS,
        iou_thresholds: Iterable[float] = COCO_IOUS,
    ) -> None:
        self.max_dets = tuple(sorted(int(m) for m in max_dets))
        if not self.max_dets or self.max_dets[0] < 1 or self.max_dets[-1] >= 2**16:
            raise OptionError(f"max_dets must be in [1, 65535], got {self.max_dets}")
        self.areas = {str(k): (float(lo), float(hi)) for k, (lo, hi) in areas.items()}
        self.iou_thresholds = np.array(iou_thresholds, dtype=np.float64).ravel()
        if not self.areas or self.iou_thresholds.size == 0:
            raise OptionError("areas and iou_thresholds must not be empty")
        self._ranges = np.array(list(self.areas.values()), dtype=np.float64)
        n_bytes = -(-2 * len(self.areas) * self.iou_thresholds.size // 8)
        self.dtype = np.dtype(
            [
                ("score", "<f8"),
                ("category", "<i8"),
                ("order", "<i4"),
                ("rank", "<u2"),
                ("bits", "u1", (n_bytes,)),
            ]
        )
        self._records: list[np.ndarray] = []
        self._orders: list[np.ndarray] = []
        self._npig: dict[int, np.ndarray] = {}
        self._cache: tuple[np.ndarray, np.ndarray] | None = None
        self._consolidated: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def categories(self) -> list[int]:
        """Sorted categories seen, in ground truth or detections."""
        return sorted(self._npig)

    @property
    def bytes_per_detection(self) -> int:
        """Size of one detection record."""
        return self.dtype.itemsize

    def _params(self) -> tuple:
        return self.max_dets, tuple(self.areas.items()), self.iou_thresholds.tobytes()

    def update(self, images: Iterable[CocoImage]) -> None:
        """Add images: ``evaluateImg`` of each of their (image, category) pairs.

        Args:
            images: :class:`CocoImage` s, in any order, none added before.

        Examples:
            >>> s = CocoState()
            >>> s.update([CocoImage(0, [1, 1], [500.0, 2e4], [False, False], [], [], [], [])])
            >>> s.recall()[0, 0, :, 2].tolist()  # no detection: recall 0 where there are instances
            [0.0, 0.0, -1.0, 0.0]
        """
        images = list(images)
        if not images:
            return
        orders = np.array([im.order for im in images], np.int64)
        if np.unique(orders).size != orders.size:
            raise InputValueError("two images of one update have the same order")
        d_cat = np.concatenate([im.det_category for im in images])
        g_cat = np.concatenate([im.gt_category for im in images])
        cats = np.unique(np.concatenate([d_cat, g_cat]))
        g_crowd = np.concatenate([im.gt_crowd for im in images])
        g_ignore = _outside(np.concatenate([im.gt_area for im in images]), self._ranges)
        g_ignore |= g_crowd[:, None]
        counts = np.zeros((cats.size, len(self.areas)), np.int64)
        np.add.at(counts, np.searchsorted(cats, g_cat), ~g_ignore)
        if d_cat.size:
            self._records.append(self._evaluate(images, cats, d_cat, g_cat, g_ignore, g_crowd))
        self._orders.append(orders)
        self._cache = self._consolidated = None
        for c, n in zip(cats.tolist(), counts, strict=True):
            self._npig[c] = self._npig[c] + n if c in self._npig else n

    def _evaluate(self, images, cats, d_cat, g_cat, g_ignore, g_crowd) -> np.ndarray:
        """Records of the kept detections of ``images`` (``evaluateImg`` of every (image,
        category) pair, vectorised over the pairs)."""
        n_det = np.array([im.det_category.size for im in images])
        n_gt = np.array([im.gt_category.size for im in images])
        d_img, d_file = np.repeat(np.arange(len(images)), n_det), _within(n_det)
        g_img, g_col = np.repeat(np.arange(len(images)), n_gt), _within(n_gt)
        score = np.concatenate([im.det_score for im in images])
        # detections by image, category, descending score, file order; cut per (image, category)
        perm = np.lexsort((d_file, -score, d_cat, d_img))
        d_key = d_img[perm] * cats.size + np.searchsorted(cats, d_cat[perm])
        rank = _within(_runs(d_key)[2])
        keep = rank < self.max_dets[-1]
        perm, d_key, rank = perm[keep], d_key[keep], rank[keep]
        # instances by image, category, annotation order
        gperm = np.lexsort((g_col, g_cat, g_img))
        g_key = g_img[gperm] * cats.size + np.searchsorted(cats, g_cat[gperm])
        # where each kept detection's IoU row starts in the flattened matrices, each column
        iou_flat = np.concatenate([im.iou.ravel() for im in images])
        row = (np.cumsum(n_det * n_gt) - n_det * n_gt)[d_img] + d_file * n_gt[d_img]
        inputs = (iou_flat, row[perm], g_col[gperm], g_ignore[gperm], g_crowd[gperm])
        # the (image, category) pairs with both detections and instances
        dk, ds, dn = _runs(d_key)
        gk, gs, gn = _runs(g_key)
        _, di, gi = np.intersect1d(dk, gk, assume_unique=True, return_indices=True)
        A, T = len(self.areas), self.iou_thresholds.size
        matched, tp = np.zeros((perm.size, A, T), bool), np.zeros((perm.size, A, T), bool)
        for b_ds, b_dn, b_gs, b_gn in _batches(ds[di], dn[di], gs[gi], gn[gi], A * T):
            padded = _padded(*inputs, b_ds, b_dn, b_gs, b_gn)
            m, m_ig = greedy_coco_match(*padded, b_dn, self.iou_thresholds)
            p, r = np.repeat(np.arange(b_ds.size), b_dn), _within(b_dn)
            matched[b_ds[p] + r], tp[b_ds[p] + r] = m[p, r], m[p, r] & ~m_ig[p, r]
        d_out = _outside(np.concatenate([im.det_area for im in images])[perm], self._ranges)
        rec = np.empty(perm.size, self.dtype)
        rec["score"], rec["category"], rec["rank"] = score[perm], d_cat[perm], rank
        rec["order"] = np.array([im.order for im in images])[d_img[perm]]
        bits = np.concatenate([tp, ~matched & ~d_out[:, :, None]], 1)  # true, false positives
        rec["bits"] = np.packbits(bits.reshape(perm.size, -1), axis=1)
        return rec

    def _merged(self) -> tuple[np.ndarray, np.ndarray]:
        """All records and the sorted image orders (checked distinct), consolidated."""
        if self._consolidated is None:
            rec = np.concatenate([np.empty(0, self.dtype), *self._records])
            orders = np.sort(np.concatenate([np.empty(0, np.int64), *self._orders]))
            if np.any(orders[1:] == orders[:-1]):
                raise InputValueError("an image (order) was added twice")
            self._records, self._orders = [rec], [orders]
            self._consolidated = rec, orders
        return self._consolidated

    def __add__(self, other: object) -> CocoState:
        """Merge two states of disjoint image sets.

        Examples:
            >>> a, b = CocoState(), CocoState()
            >>> a.update([CocoImage(0, [1], [500.0], [False], [], [], [], np.zeros((0, 1)))])
            >>> b.update([CocoImage(1, [], [], [], [1], [0.9], [480.0], np.zeros((1, 0)))])
            >>> float((a + b).stats()[0])  # one instance, one false alarm in another image
            0.0
        """
        if not isinstance(other, CocoState):
            return NotImplemented
        if self._params() != other._params():
            raise OptionError("cannot merge CocoStates with different parameters")
        out = CocoState(
            max_dets=self.max_dets, areas=self.areas, iou_thresholds=self.iou_thresholds
        )
        (ra, oa), (rb, ob) = self._merged(), other._merged()
        out._records, out._orders = [ra, rb], [oa, ob]
        out._merged()
        for npig in (self._npig, other._npig):
            for c, n in npig.items():
                out._npig[c] = out._npig[c] + n if c in out._npig else n.copy()
        return out

    def __radd__(self, other: object) -> CocoState:
        """``0 + state`` is ``state`` (so ``sum(states)`` works)."""
        return self if isinstance(other, int) and other == 0 else NotImplemented

    def _canonical(self) -> np.ndarray:
        rec, _ = self._merged()
        return rec[np.lexsort((rec["rank"], rec["order"], rec["category"]))]

    def __eq__(self, other: object) -> bool:
        """Equal parameters, images, ground-truth counts and detection records (whatever the
        split into updates and the order of merges).

        Examples:
            >>> ims = [CocoImage(i, [1], [500.0], [False], [1], [0.5], [480.0], [[0.6]])
            ...        for i in range(3)]
            >>> a, b, c = CocoState(), CocoState(), CocoState()
            >>> a.update(ims); b.update(ims[2:]); c.update(ims[:2])
            >>> a == b + c == c + b
            True
        """
        if not isinstance(other, CocoState):
            return NotImplemented
        return (
            self._params() == other._params()
            and np.array_equal(self._merged()[1], other._merged()[1])
            and self._npig.keys() == other._npig.keys()
            and all(np.array_equal(n, other._npig[c]) for c, n in self._npig.items())
            and self._canonical().tobytes() == other._canonical().tobytes()
        )

    def _accumulate(self) -> tuple[np.ndarray, np.ndarray]:
        """``COCOeval.accumulate``: ``(precision (T, R, K, A, M), recall (T, K, A, M))``."""
        if self._cache is None:
            rec, _ = self._merged()
            rec = rec[np.lexsort((rec["rank"], rec["order"], -rec["score"], rec["category"]))]
            cats = self.categories
            lo = np.searchsorted(rec["category"], cats, "left")
            hi = np.searchsorted(rec["category"], cats, "right")
            curves = [
                _category_curves(
                    rec[lo[k] : hi[k]], self._npig[c], self.max_dets, self.iou_thresholds.size
                )
                for k, c in enumerate(cats)
            ]
            T, A, M = self.iou_thresholds.size, len(self.areas), len(self.max_dets)
            self._cache = (
                np.stack([p for p, _ in curves], 2)
                if curves
                else -np.ones((T, RECALL_POINTS.size, 0, A, M)),
                np.stack([r for _, r in curves], 1) if curves else -np.ones((T, 0, A, M)),
            )
        return self._cache

    def _slots(self, array: np.ndarray, axis: int, categories) -> np.ndarray:
        """``array`` with its category axis in the order of ``categories`` (``None``: as
        :attr:`categories`), -1 for a category never seen (as pycocotools fills it)."""
        if categories is None:
            return array.copy()
        seen = {c: k for k, c in enumerate(self.categories)}
        shape = list(array.shape)
        shape[axis] = len(categories)
        out = -np.ones(shape)
        for k, c in enumerate(categories):
            if c in seen:
                np.moveaxis(out, axis, 0)[k] = np.moveaxis(array, axis, 0)[seen[c]]
        return out

    def precision(self, categories=None) -> np.ndarray:
        """``COCOeval.eval["precision"]``: ``(T, R, K, A, M)``, -1 where a category has no
        non-ignored ground truth in an area range; ``K`` is :attr:`categories`, or the
        category ids given (a dataset's whole list, as pycocotools lays them out: -1 for a
        category never seen).

        Examples:
            >>> s = CocoState()
            >>> s.update([CocoImage(0, [1], [500.0], [False], [1], [0.9], [480.0], [[0.8]])])
            >>> s.precision()[[0, 7], 50, 0, 0, 2].round(6).tolist()  # IoU 0.8: at 0.5, not 0.85
            [1.0, 0.0]
        """
        return self._slots(self._accumulate()[0], 2, categories)

    def recall(self, categories=None) -> np.ndarray:
        """``COCOeval.eval["recall"]``: ``(T, K, A, M)``, -1 as :meth:`precision` (and the
        same ``categories``).

        Examples:
            >>> s = CocoState()
            >>> s.update([CocoImage(0, [1], [500.0], [False], [1], [0.9], [480.0], [[0.8]])])
            >>> s.recall()[[0, 7], 0, 2, 2].tolist()  # no medium instance
            [-1.0, -1.0]
        """
        return self._slots(self._accumulate()[1], 1, categories)

    def stats(self) -> np.ndarray:
        """``COCOeval.stats``: the 12 summary numbers (see :func:`summarize`).

        Examples:
            >>> CocoState().stats()[:3].tolist()  # nothing to score
            [-1.0, -1.0, -1.0]
        """
        precision, recall = self._accumulate()
        return summarize(precision, recall, self.iou_thresholds, list(self.areas), self.max_dets)


def _category_curves(
    rec: np.ndarray, npig: np.ndarray, max_dets: tuple[int, ...], T: int
) -> tuple[np.ndarray, np.ndarray]:
    """``accumulate`` for one category: precision ``(T, R, A, M)`` and recall ``(T, A, M)``.

    Args:
        rec: the category's records, ranked (score descending, image order, rank).
        npig: ``(A,)`` non-ignored instances per area range (-1 entries where 0).
        max_dets: the caps.
        T: IoU thresholds.

    Examples:
        >>> s = CocoState(areas={"all": (0, 1e10)})
        >>> s.update([CocoImage(0, [1], [500.0], [False], [1], [0.9], [480.0], [[0.8]])])
        >>> p, r = _category_curves(s._merged()[0], np.array([1]), (1, 10, 100), 10)
        >>> r[:, 0, 0].tolist()
        [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0]
    """
    A, M = npig.size, len(max_dets)
    precision, recall = -np.ones((T, RECALL_POINTS.size, A, M)), -np.ones((T, A, M))
    if not npig.any():
        return precision, recall
    bits = np.unpackbits(rec["bits"], axis=1, count=2 * A * T)
    dtype = np.int32 if rec.size < 2**31 else np.int64
    for m, cap in enumerate(max_dets):
        # cumulative true / false positive counts along contiguous rows (2, A, T, detections)
        kept = np.ascontiguousarray(bits[rec["rank"] < cap].T)
        tp, fp = np.cumsum(kept, -1, dtype=dtype).reshape(2, A, T, -1)
        for a in np.flatnonzero(npig):
            for t in range(T):
                q, r = interpolated_precision(tp[a, t], fp[a, t], int(npig[a]))
                precision[t, :, a, m], recall[t, a, m] = q, r
    return precision, recall


def _padded(iou_flat, row, col, ignore, crowd, ds, dn, gs, gn):
    """The matcher's padded inputs for a batch of problems.

    Args:
        iou_flat: the flattened IoU matrices.
        row: per ranked detection, where its IoU row starts in ``iou_flat``.
        col: per sorted instance, its column; ``ignore`` ``(N, A)``, ``crowd`` ``(N,)``: flags.
        ds, dn, gs, gn: per problem, its first detection and instance and their counts.

    Returns:
        ``iou (P, D, G)`` (``-inf`` padding), ``ignore (P, A, G)``, ``crowd (P, G)``.

    Examples:
        >>> iou, ignore, crowd = _padded(np.array([0.1, 0.2, 0.3]), np.array([0, 1]),
        ...     np.array([0, 1]), np.zeros((2, 1), bool), np.zeros(2, bool),
        ...     np.array([0, 1]), np.array([1, 1]), np.array([0, 1]), np.array([1, 1]))
        >>> iou[:, 0].tolist()  # problem 1: the row starting at 1, column 1
        [[0.1], [0.3]]
    """
    P, D, G = ds.size, int(dn.max()), int(gn.max())
    pairs = dn * gn
    p = np.repeat(np.arange(P), pairs)
    r, q = np.divmod(_within(pairs), gn[p])
    out_iou = np.full((P, D, G), -np.inf)
    out_iou[p, r, q] = iou_flat[row[ds[p] + r] + col[gs[p] + q]]
    p, q = np.repeat(np.arange(P), gn), _within(gn)
    out_ignore = np.ones((P, ignore.shape[1], G), bool)
    out_ignore[p, :, q] = ignore[gs[p] + q]
    out_crowd = np.zeros((P, G), bool)
    out_crowd[p, q] = crowd[gs[p] + q]
    return out_iou, out_ignore, out_crowd


def _batches(ds, dn, gs, gn, width: int):
    """Problems grouped by instance count (power-of-two padding), most detections first, in
    batches whose matcher arrays (IoUs, and instances or detections times ``width`` area ranges
    and thresholds, per problem) stay under ``_WORK`` elements.

    Examples:
        >>> ds, dn, gs, gn = np.array([[0, 2, 3], [2, 1, 5], [0, 1, 4], [1, 3, 4]])
        >>> [b[3].tolist() for b in _batches(ds, dn, gs, gn, 40)]  # instances per problem
        [[1], [4, 3]]
    """
    pad = 1 << np.ceil(np.log2(np.maximum(gn, 1))).astype(np.int64)
    for g in np.unique(pad):
        idx = np.flatnonzero(pad == g)
        idx = idx[np.argsort(-dn[idx], kind="stable")]
        d = int(dn[idx[0]])
        step = max(1, _WORK // (d * int(g) + max(d, int(g)) * width))
        for i in range(0, idx.size, step):
            j = idx[i : i + step]
            yield ds[j], dn[j], gs[j], gn[j]
