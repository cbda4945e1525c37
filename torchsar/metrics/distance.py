"""One-to-one matching of point detections to point ground truth by distance, and the xView3
length-estimation score.

For detectors that output centroids only (ship detection on Sentinel-1, xView3-SAR), a
detection and a ground-truth point form a pair when they are closer than a tolerance, in
pixels or in metres (``(row_m, col_m)`` pixel spacing, possibly anisotropic).

Reference: Paolo et al., "xView3-SAR: Detecting Dark Fishing Activity Using Synthetic Aperture
Radar Imagery", NeurIPS 2022 Datasets and Benchmarks (arXiv:2206.00897), and its scoring code
``reference/metric.py`` of https://github.com/DIUx-xView/xview3-reference (the revision with
the ``costly_dist`` and ``drop_low_detect`` options, both on in the official scoring, e.g.
``official_metric_scoring`` in ``xview3/metric.py`` of the first-place solution,
https://github.com/BloodAxe/xView3-The-First-Place-Solution). That code, per scene:

- builds ``dist = scipy.spatial.distance_matrix(pred, gt, p=2) * PIX_TO_M`` from
  ``(row, column)`` pixel positions (``PIX_TO_M = 10``: isotropic 10 m pixels);
- with ``costly_dist``, sets the entries ``> distance_tolerance`` (200 m) to ``9999999 *
  PIX_TO_M`` and runs ``scipy.optimize.linear_sum_assignment(dist)``: so the assignment first
  maximises the number of pairs at most the tolerance apart, then minimises their total
  distance;
- keeps as true positives the assigned pairs with ``dist < distance_tolerance`` (strictly:
  a pair exactly at the tolerance is not a match); unassigned detections are false
  positives, unassigned ground truth false negatives;
- "don't care" ground truth (``confidence == "LOW"``): with ``drop_low_detect`` it first
  runs the same assignment against all the scene's ground truth (HIGH, MEDIUM and LOW) and
  drops the detections assigned to a LOW point within the tolerance; the remaining
  detections are then scored against the HIGH and MEDIUM points only. LOW points are never
  false negatives, and each absorbs at most one detection;
- length (``compute_length_performance``): over the true-positive pairs whose ground-truth
  length is known, caps both lengths at ``MAX_OBJECT_LENGTH_M = 500`` m, averages
  ``|pred - true| / true`` and scores ``1 - min(mean, 1)`` (0 when no pair qualifies; only
  the true length is checked for NaN).

Here:

- :func:`pair_distances` computes the same matrix (``sqrt(dr^2 + dc^2) * spacing``, the same
  floating-point operations as xView3 for isotropic spacing), or with anisotropic spacing
  ``sqrt((dr * row_m)^2 + (dc * col_m)^2)``.
- :func:`optimal_match` is xView3's assignment with out-of-range pairs forbidden and the
  tolerance strict for eligibility as well as for counting. xView3's ``costly_dist`` only
  makes pairs *beyond* the tolerance costly, so a pair exactly *at* it may take part in the
  assignment and then not count; it can then find fewer matches than the maximum (only when
  some distance equals the tolerance exactly, as integer pixel offsets such as (12, 16) at
  10 m give 200 m). Here every count is the maximum number of pairs strictly within the
  tolerance.
- :func:`greedy_match_by_score` is the greedy alternative, nested by score (one pass gives
  every point of a PR / FROC curve), as the IoU matchers of
  :mod:`torchsar.metrics.matching`.
- :func:`dont_care` marks unmatched detections strictly within the tolerance of a don't-care
  point: neither true nor false positives. Unlike xView3 it runs after the matching to the
  cared-for ground truth (a real match has priority), and a don't-care point absorbs any
  number of detections (the COCO crowd rule of :mod:`torchsar.metrics.matching`); xView3's
  one-to-one pass can leave a second detection near the same LOW point a false positive, or
  take a detection away from a HIGH point that has no other.
- :func:`length_score` / :class:`LengthErrors` follow ``compute_length_performance`` with the
  500 m cap, skip pairs where either length is unknown (NaN), and give NaN (not 0) when no
  pair qualifies. Relative errors are summed in integer units of 1e-9, so partial sums merge
  exactly in any order.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from numbers import Real

import numpy as np
from scipy.optimize import linear_sum_assignment

from torchsar.errors import InputValueError, OptionError, ShapeError

__all__ = [
    "MAX_LENGTH_M",
    "LengthErrors",
    "dont_care",
    "greedy_match_by_score",
    "length_score",
    "optimal_match",
    "pair_distances",
    "parse_distance",
]

MAX_LENGTH_M = 500.0
"""xView3's cap on both lengths before the relative error (``MAX_OBJECT_LENGTH_M``)."""

_NANO = 10**9  # relative errors are summed in units of 1e-9

_DISTANCE = re.compile(
    r"\s*(?P<num>[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|[+-]?(?:nan|inf(?:inity)?))"
    r"\s*(?P<unit>[A-Za-z]*)\s*",
    re.IGNORECASE,
)


def _array(x: object, name: str) -> np.ndarray:
    try:
        return np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputValueError(f"{name} must be an array of real numbers, got {x!r:.60}") from None


def _points(x: object, name: str) -> np.ndarray:
    """``(N, 2)`` finite ``(row, col)`` points; an empty array of any shape is ``(0, 2)``."""
    a = _array(x, name)
    if a.size == 0:
        return a.reshape(0, 2)
    if a.ndim != 2 or a.shape[1] != 2:
        raise ShapeError(f"{name} must have shape (N, 2) (row, col), got {a.shape}")
    if not np.isfinite(a).all():
        raise InputValueError(f"{name} must be finite, got {int((~np.isfinite(a)).sum())} NaN/Inf")
    return a


def _distances(x: object, name: str, ndim: int) -> np.ndarray:
    """Distances: no NaN, non-negative (``inf`` allowed: too far for anything)."""
    a = _array(x, name)
    if a.ndim != ndim:
        axes = "(D, G)" if ndim == 2 else "(D,)"
        raise ShapeError(f"{name} must have shape {axes}, got {a.shape}")
    if np.isnan(a).any() or (a < 0).any():
        raise InputValueError(f"{name} must hold distances >= 0 (inf allowed), without NaN")
    return a


def _tolerance(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not 0 < value < math.inf:
        raise OptionError(f"max_distance must be a finite number > 0, got {value!r}")
    return float(value)


def _spacing(value: object) -> tuple[float, float]:
    ok = isinstance(value, tuple | list) and len(value) == 2
    ok = ok and all(isinstance(v, Real) and not isinstance(v, bool) for v in value)
    ok = ok and all(0 < v < math.inf for v in value)
    if not ok:
        raise OptionError(
            f"spacing must be a pair (row_m, col_m) of finite pixel spacings > 0 in metres, "
            f"got {value!r}"
        )
    return float(value[0]), float(value[1])


def _same_length(d: int, a: np.ndarray, name: str, what: str = "(D,)") -> None:
    if a.shape != (d,):
        raise ShapeError(f"{name} must have shape {what} with D = {d}, got {a.shape}")


def parse_distance(text: str) -> tuple[float, str]:
    """Parse a distance tolerance such as ``"200m"``, ``"200 m"``, ``"20px"`` or ``"20"``.

    Args:
        text: a positive finite number followed by ``m`` (metres) or ``px`` (pixels); no
            unit means pixels.

    Returns:
        ``(value, unit)`` with ``unit`` ``"m"`` or ``"px"``.

    Raises:
        OptionError: (naming ``max_distance``) not a number, zero, negative, NaN, Inf, or a
            unit other than ``m`` / ``px``.

    Examples:
        >>> parse_distance("200 m"), parse_distance("20")
        ((200.0, 'm'), (20.0, 'px'))
    """
    hint = "e.g. '200m', '200 m', '20px' or '20' (pixels)"
    match = _DISTANCE.fullmatch(text) if isinstance(text, str) else None
    if match is None:
        raise OptionError(f"max_distance must be a number with unit m or px, {hint}; got {text!r}")
    value, unit = float(match["num"]), match["unit"] or "px"
    if unit not in ("m", "px"):
        raise OptionError(
            f"max_distance has unknown unit {unit!r} in {text!r}: use m (metres) or px (pixels)"
        )
    if not 0 < value < math.inf:
        raise OptionError(f"max_distance must be finite and > 0, {hint}; got {text!r}")
    return value, unit


def pair_distances(
    det: np.ndarray, gt: np.ndarray, spacing: tuple[float, float] | None = None
) -> np.ndarray:
    """Distances ``(D, G)`` between detections and ground-truth points.

    Args:
        det: ``(D, 2)`` detection positions ``(row, col)`` in pixels (sub-pixel allowed).
        gt: ``(G, 2)`` ground-truth positions ``(row, col)`` in pixels.
        spacing: ``(row_m, col_m)`` pixel spacing in metres: distances in metres, the two
            axes scaled separately; ``None``: distances in pixels.

    Returns:
        float64 ``(D, G)``. With isotropic spacing ``s`` this is ``sqrt(dr^2 + dc^2) * s``,
        the operations of xView3's ``distance_matrix(...) * PIX_TO_M``.

    Raises:
        ShapeError: ``det`` / ``gt`` not ``(N, 2)``.
        InputValueError: NaN or Inf positions.
        OptionError: ``spacing`` not a pair of finite spacings > 0.

    Examples:
        >>> pair_distances(np.array([[0.0, 0.0]]), np.array([[3.0, 4.0], [4.0, 0.0]]))
        array([[5., 4.]])
        >>> pair_distances(np.array([[0.0, 0.0]]), np.array([[3.0, 4.0], [4.0, 0.0]]), (0.5, 2.0))
        array([[8.1394103, 2.       ]])
    """
    d, g = _points(det, "det"), _points(gt, "gt")
    dr = d[:, None, 0] - g[None, :, 0]
    dc = d[:, None, 1] - g[None, :, 1]
    with np.errstate(over="ignore"):  # beyond 1e154 pixels: inf, too far for any tolerance
        if spacing is None:
            return np.sqrt(dr * dr + dc * dc)
        row_m, col_m = _spacing(spacing)
        if row_m == col_m:
            return np.sqrt(dr * dr + dc * dc) * row_m
        dr, dc = dr * row_m, dc * col_m
        return np.sqrt(dr * dr + dc * dc)


def optimal_match(dist: np.ndarray, max_distance: float) -> np.ndarray:
    """Optimal one-to-one matching within a distance (xView3's Hungarian assignment).

    Among the one-to-one matchings whose pairs are all strictly closer than
    ``max_distance``, one with the most pairs and, among those, the least total distance
    (``scipy.optimize.linear_sum_assignment``, out-of-range pairs forbidden). A pair exactly
    at ``max_distance`` does not match, as in xView3 (``dist < distance_tolerance``). Ties
    between equally good matchings are broken by the solver.

    Args:
        dist: ``(D, G)`` distances (:func:`pair_distances`); ``inf`` never matches.
        max_distance: the tolerance, in the unit of ``dist``.

    Returns:
        int64 ``(D,)``: the ground-truth column matched to each detection, -1 unmatched.

    Raises:
        ShapeError: ``dist`` not 2-D.
        InputValueError: NaN or negative distances.
        OptionError: ``max_distance`` not finite and > 0.

    Examples:
        >>> dist = np.array([[1.0, 2.0], [1.5, 9.0]])  # greedy nearest-first would pair one
        >>> optimal_match(dist, 5.0)
        array([1, 0])
    """
    dist = _distances(dist, "dist", 2)
    tol = _tolerance(max_distance)
    out = np.full(dist.shape[0], -1, dtype=np.int64)
    near = dist < tol
    rows, cols = np.flatnonzero(near.any(axis=1)), np.flatnonzero(near.any(axis=0))
    if rows.size == 0:
        return out
    near = near[np.ix_(rows, cols)]
    # A forbidden pair costs more than any set of allowed pairs (each < tol) together, so the
    # full rectangular assignment maximises the allowed pairs first, then minimises their sum.
    forbidden = tol * (min(rows.size, cols.size) + 1)
    cost = np.where(near, dist[np.ix_(rows, cols)], forbidden)
    r, c = linear_sum_assignment(cost)
    keep = near[r, c]
    out[rows[r[keep]]] = cols[c[keep]]
    return out


def greedy_match_by_score(dist: np.ndarray, score: np.ndarray, max_distance: float) -> np.ndarray:
    """Greedy one-to-one matching by descending score, nearest free point first.

    Detections are visited in descending score order (stable: equal scores keep their input
    order); each takes the nearest still-unmatched ground-truth point strictly closer than
    ``max_distance`` (equal distances: the lowest column). The matches among the detections
    above any score are those of the full pass, so one pass gives a whole FROC / AP curve.

    Args:
        dist: ``(D, G)`` distances (:func:`pair_distances`).
        score: ``(D,)`` detection scores (no NaN).
        max_distance: the tolerance, in the unit of ``dist``.

    Returns:
        int64 ``(D,)``: the ground-truth column matched to each detection, -1 unmatched.

    Raises:
        ShapeError: ``dist`` not 2-D or ``score`` not ``(D,)``.
        InputValueError: NaN or negative distances, NaN scores.
        OptionError: ``max_distance`` not finite and > 0.

    Examples:
        >>> dist = np.array([[1.0, 2.0], [1.5, 9.0]])
        >>> greedy_match_by_score(dist, np.array([0.9, 0.8]), 5.0)  # the second is left over
        array([ 0, -1])
    """
    dist = _distances(dist, "dist", 2)
    score = _array(score, "score")
    _same_length(dist.shape[0], score, "score")
    if np.isnan(score).any():
        raise InputValueError("score must not hold NaN")
    tol = _tolerance(max_distance)
    out = np.full(dist.shape[0], -1, dtype=np.int64)
    if dist.shape[1] == 0:
        return out
    taken = dist >= tol  # out of range, or (per column, below) already matched
    for i in np.argsort(-score, kind="stable"):
        j = int(np.argmin(np.where(taken[i], np.inf, dist[i])))
        if not taken[i, j]:
            out[i] = j
            taken[:, j] = True
    return out


def dont_care(
    det: np.ndarray, matched: np.ndarray, ignore_dist: np.ndarray, max_distance: float
) -> np.ndarray:
    """Unmatched detections near a don't-care point (e.g. xView3's LOW-confidence labels).

    Such detections are neither true nor false positives. Don't-care points are not part of
    the ground truth that is matched (they are never false negatives); this runs after the
    matching, so a match to real ground truth has priority, and one don't-care point may
    absorb several detections (see the module notes for how xView3 differs).

    Args:
        det: ``(D, 2)`` detection positions; only fixes ``D`` (the other arguments are
            checked against it).
        matched: int ``(D,)`` the matching (:func:`optimal_match` or
            :func:`greedy_match_by_score`), negative = unmatched.
        ignore_dist: ``(D,)`` distance of each detection to its nearest don't-care point
            (``inf`` when there is none), in the unit of ``max_distance``.
        max_distance: the tolerance of the matching; strictly closer counts.

    Returns:
        bool ``(D,)``.

    Raises:
        ShapeError: shapes that do not agree with ``det``.
        InputValueError: NaN or negative ``ignore_dist``, non-integer ``matched``.
        OptionError: ``max_distance`` not finite and > 0.

    Examples:
        >>> det = np.array([[0.0, 0.0], [0.0, 50.0], [0.0, 90.0]])
        >>> dont_care(det, np.array([0, -1, -1]), np.array([1.0, 3.0, np.inf]), 20.0)
        array([False,  True, False])
    """
    d = _points(det, "det").shape[0]
    m = np.asarray(matched)
    _same_length(d, m, "matched")
    if m.size and not np.issubdtype(m.dtype, np.integer):
        raise InputValueError(f"matched must hold integer columns (-1: unmatched), got {m.dtype}")
    near = _distances(ignore_dist, "ignore_dist", 1)
    _same_length(d, near, "ignore_dist")
    return (m < 0) & (near < _tolerance(max_distance))


def _lengths(x: object, name: str, *, zero_ok: bool) -> np.ndarray:
    a = _array(x, name)
    if a.ndim != 1:
        raise ShapeError(f"{name} must have shape (K,), one length per matched pair; got {a.shape}")
    bad = a < 0 if zero_ok else a <= 0
    if bad.any():
        bound = ">= 0" if zero_ok else "> 0"
        raise InputValueError(f"{name} must hold lengths {bound} in metres or NaN (unknown)")
    return a


@dataclass(frozen=True)
class LengthErrors:
    """Additive state of the xView3 length score: sums merge exactly, in any order.

    Attributes:
        nano: sum over pairs of the capped relative length error, each rounded to an
            integer number of 1e-9 (so partial sums add exactly).
        count: number of pairs with both lengths known.

    Examples:
        >>> a = LengthErrors().add(np.array([110.0]), np.array([100.0]))
        >>> b = LengthErrors().add(np.array([90.0, 7.0]), np.array([100.0, np.nan]))
        >>> (a + b).count, round((a + b).score, 9)
        (2, 0.9)
    """

    nano: int = 0
    count: int = 0

    def add(self, pred_m: np.ndarray, true_m: np.ndarray) -> LengthErrors:
        """This state plus matched pairs ``(K,)`` of predicted and true lengths in metres.

        Pairs where either length is NaN are skipped. Both lengths are capped at
        :data:`MAX_LENGTH_M` (500 m) before the relative error ``|pred - true| / true``.

        Raises:
            ShapeError: not two ``(K,)`` arrays of the same length.
            InputValueError: negative predictions, true lengths <= 0, or true lengths so
                small that the relative error overflows.
        """
        pred = _lengths(pred_m, "pred_m", zero_ok=True)
        true = _lengths(true_m, "true_m", zero_ok=False)
        _same_length(pred.shape[0], true, "true_m", "(K,) like pred_m")
        known = ~(np.isnan(pred) | np.isnan(true))
        p = np.minimum(pred[known], MAX_LENGTH_M)
        t = np.minimum(true[known], MAX_LENGTH_M)
        with np.errstate(over="ignore"):
            units = np.rint(np.abs(p - t) / t * _NANO)
        if not np.isfinite(units).all():
            raise InputValueError("true_m holds lengths too close to 0 (relative error overflows)")
        nano = sum(int(u) for u in units.tolist())
        return LengthErrors(self.nano + nano, self.count + int(known.sum()))

    def __add__(self, other: LengthErrors) -> LengthErrors:
        if not isinstance(other, LengthErrors):
            return NotImplemented
        return LengthErrors(self.nano + other.nano, self.count + other.count)

    @property
    def score(self) -> float:
        """``1 - min(mean relative error, 1)`` in [0, 1]; NaN when no pair was counted."""
        if self.count == 0:
            return math.nan
        return 1.0 - min(self.nano / (self.count * _NANO), 1.0)


def length_score(pred_m: np.ndarray, true_m: np.ndarray) -> float:
    """xView3's length-estimation score over matched pairs: ``1 - min(mean relative error, 1)``.

    The relative error of a pair is ``|min(pred, 500) - min(true, 500)| / min(true, 500)``;
    pairs with either length unknown (NaN) are skipped. Equal to
    ``LengthErrors().add(pred_m, true_m).score`` (each error rounded to 1e-9).

    Args:
        pred_m: ``(K,)`` predicted lengths in metres of the matched detections.
        true_m: ``(K,)`` true lengths in metres of the ground truth they matched.

    Returns:
        The score in [0, 1]; NaN when no pair has both lengths (xView3 reports 0 there).

    Raises:
        ShapeError: not two ``(K,)`` arrays of the same length.
        InputValueError: negative predictions or true lengths <= 0.

    Examples:
        >>> length_score(np.array([110.0, 90.0, 600.0, 5.0]),
        ...              np.array([100.0, 100.0, 400.0, np.nan]))
        0.85
    """
    return LengthErrors().add(pred_m, true_m).score
