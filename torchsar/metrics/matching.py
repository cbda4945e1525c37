"""One-to-one matching of scored objects to ground-truth instances.

The COCO rule (Lin et al., "Microsoft COCO: Common Objects in Context", ECCV 2014,
doi:10.1007/978-3-319-10602-1_48; the ``pycocotools`` evaluator): detections are visited in
descending score order; each takes the still-unmatched ground-truth instance of highest
quality (mask or box IoU) at or above the threshold; an instance is matched at most once; a
detection matching nothing real but lying on a don't-care region (COCO "crowd": intersection
over the detection's own area) is ignored, neither true nor false. Matching is per class when
the detections carry classes (``classes="auto"``, COCO's ``useCats``), or class-agnostic
(``classes="agnostic"``). So one blob
over two targets is at most one true positive, and a flood of the whole image is one false
alarm. Because the visit is greedy by score, the matches among the detections scoring above
any level are exactly those of the full pass: one pass gives every point of a PR / FROC curve.

The prescreening rule (``kind="centroid"``), common for SAR vehicle prescreeners: a detection
hits an instance when its centroid lies inside the instance's box grown by ``margin`` (a
fraction of the box's larger side) and its box is at most ``max_size_ratio`` times the
instance's box area; among several, the nearest box centre; the same greedy one-to-one visit.

The distance rule (``kind="distance"``), for point detectors (xView3-SAR): a detection's
centroid and an instance's centroid pair up when closer than ``max_distance`` (pixels, or
metres with each image's pixel spacing); see :mod:`torchsar.metrics.points`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from torchsar._checks import check_choice
from torchsar.errors import OptionError
from torchsar.metrics.greedy import greedy_assign
from torchsar.metrics.truth import GroundTruth, Regions, ground_truth

__all__ = [
    "CLASSES",
    "COCO_IOUS",
    "GroundTruth",
    "Matching",
    "Regions",
    "box_iou",
    "greedy_match",
    "ground_truth",
    "pair_box_iou",
]

COCO_IOUS = np.linspace(0.5, 0.95, 10)
"""The IoU thresholds of COCO's AP@[.5:.95], exactly as ``pycocotools`` computes them (its
0.9 is 0.8999999999999999: rounding it would refuse an IoU of exactly that value)."""

UNMATCHED, IGNORED = -1, -2
CLASSES = ("auto", "agnostic")
"""Class policies: ``"auto"`` matches detections that carry classes within their class (and
reports AP as the mean over classes); ``"agnostic"`` pools every class."""


@dataclass(frozen=True)
class Matching:
    """The matching rule of the operating-point metrics and the FROC.

    Attributes:
        kind: ``"mask"`` (mask IoU), ``"box"`` (box IoU), ``"centroid"`` (prescreening) or
            ``"distance"`` (points closer than ``max_distance``).
        iou: IoU threshold of ``mask`` / ``box`` (0.5: PASCAL VOC / COCO AP50).
        margin: ``centroid`` rule: box growth, as a fraction of the box's larger side.
        max_size_ratio: ``centroid`` rule: largest detection-box / instance-box area ratio.
        max_distance: ``distance`` rule: the tolerance (strict), in ``distance_units``.
        distance_units: ``"px"`` or ``"m"`` (with each image's pixel spacing).
        assign: ``distance`` rule at the operating point: ``"optimal"`` (the most pairs,
            then the least total distance, as xView3-SAR) or ``"greedy"`` (by score). AP and
            the FROC always use the greedy visit by score.
        classes: :data:`CLASSES`: per class when the detections carry classes (``"auto"``),
            or class-agnostic.
    """

    kind: str = "mask"
    iou: float = 0.5
    margin: float = 0.25
    max_size_ratio: float = 4.0
    max_distance: float | None = None
    distance_units: str = "px"
    assign: str = "optimal"
    classes: str = "auto"

    def __post_init__(self) -> None:
        check_choice(self.kind, "kind", ("mask", "box", "centroid", "distance"))
        check_choice(self.classes, "classes", CLASSES)
        for name, lo, hi in (("iou", 0.0, 1.0), ("margin", 0.0, 10.0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= v <= hi:
                raise OptionError(f"{name} must be in [{lo:g}, {hi:g}], got {v!r}")
        r = self.max_size_ratio
        if isinstance(r, bool) or not isinstance(r, int | float) or not r >= 1:
            raise OptionError(f"max_size_ratio must be >= 1, got {r!r}")
        check_choice(self.distance_units, "distance_units", ("px", "m"))
        check_choice(self.assign, "assign", ("optimal", "greedy"))
        d = self.max_distance
        if self.kind == "distance" and d is None:
            raise OptionError("the distance rule needs max_distance (pixels or metres)")
        if d is not None and (
            isinstance(d, bool) or not isinstance(d, int | float) or not 0 < d < float("inf")
        ):
            raise OptionError(f"max_distance must be a finite number > 0, got {d!r}")

    @property
    def iou_kind(self) -> str:
        """The IoU used for AP: box IoU under the box rule, mask IoU otherwise."""
        return "box" if self.kind == "box" else "mask"

    def describe(self, measured: str = "") -> str:
        """The rule in a few words, naming the IoU a row ``measured`` (``"mask"``,
        ``"box"``, ``"mask+box"``; default: the rule's own); under the centroid rule, AP's
        IoU too.

        Examples:
            >>> Matching().describe("box"), Matching(kind="distance", max_distance=10).describe()
            ('box IoU >= 0.5', 'distance < 10 px (optimal)')
            >>> Matching(kind="centroid").describe("mask")
            'centroid in target box +0.25, box <= 4x area (AP: mask IoU)'
        """
        if self.kind == "distance":
            return f"distance < {self.max_distance:g} {self.distance_units} ({self.assign})"
        if self.kind == "centroid":
            return (
                f"centroid in target box +{self.margin:g}, box <= {self.max_size_ratio:g}x "
                f"area (AP: {measured or self.iou_kind} IoU)"
            )
        return f"{measured or self.iou_kind} IoU >= {self.iou:g}"

    def as_dict(self) -> dict:
        return asdict(self)


def box_iou(a: np.ndarray, b: np.ndarray, *, crowd: bool = False) -> np.ndarray:
    """IoU matrix ``(len(a), len(b))`` of end-exclusive boxes ``(r0, c0, r1, c1)``; with
    ``crowd`` the intersection over the area of ``a`` (COCO's crowd rule).

    Examples:
        >>> box_iou(np.array([[0, 0, 2, 2.]]), np.array([[0, 1, 2, 3.]])).tolist()
        [[0.3333333333333333]]
    """
    return pair_box_iou(a[:, None, :], b[None, :, :], crowd=crowd)


def pair_box_iou(a: np.ndarray, b: np.ndarray, *, crowd: bool = False) -> np.ndarray:
    """:func:`box_iou` of boxes ``a[..., :]`` and ``b[..., :]`` paired by broadcasting
    (a finite box whose area overflows has area ``inf``: IoU 0 with any finite box)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return _pair_box_iou(a, b, crowd)


def _pair_box_iou(a: np.ndarray, b: np.ndarray, crowd: bool) -> np.ndarray:
    ih = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0, None)
    iw = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0, None)
    inter = ih * iw
    area_a = (a[..., 2] - a[..., 0]) * (a[..., 3] - a[..., 1])
    area_b = (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1])
    den = area_a if crowd else area_a + area_b - inter
    return np.where(den > 0, inter / np.where(den > 0, den, 1.0), 0.0)


def greedy_match(quality: np.ndarray, crowd: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    """COCO's greedy one-to-one assignment of one image at several thresholds at once
    (:func:`~torchsar.metrics.greedy.greedy_assign`, one problem, crowd as one region).

    Args:
        quality: ``(D, G)`` pair quality (IoU), detections already in descending score order.
        crowd: ``(D,)`` quality against the don't-care region (used only when no instance
            matches).
        thresholds: ``(T,)`` minimum quality (a pair at exactly the threshold matches).

    Returns:
        int ``(T, D)``: the matched instance column, ``-1`` unmatched, ``-2`` ignored.
        Among instances of equal quality the last one wins, as in ``pycocotools``.

    Examples:
        >>> greedy_match(np.array([[0.9, 0.6], [0.8, 0.0]]), np.zeros(2), np.array([0.5]))
        array([[ 0, -1]])
    """
    q = np.asarray(quality, np.float64)
    d, g = q.shape
    full = np.concatenate(
        [np.where(q > 0, q, -np.inf), np.asarray(crowd, np.float64)[:, None]], axis=1
    )
    full[:, -1] = np.where(full[:, -1] > 0, full[:, -1], -np.inf)
    is_crowd = np.r_[np.zeros(g, bool), True]
    col = greedy_assign(
        full[None], is_crowd[None, None], is_crowd[None], np.array([d]), thresholds
    )[0, :, 0, :].T
    return np.where(col == g, IGNORED, col).astype(np.int64)
