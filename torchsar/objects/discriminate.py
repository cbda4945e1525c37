"""The discrimination stage: a detector's output -> scored objects, the same for every detector.

detection statistic -> normalised score -> mask ``score > floor`` -> optional closing ->
connected components -> size rules -> :class:`Objects` (score, area, box, centroid,
length / width, and a label map for mask overlaps).

Two score scales (``scale=``):

- ``"statistic"``: an object's score is the peak of the detector's own statistic over its
  pixels and the operating threshold is the design threshold itself (one value for the
  whole batch): a probability map stays probabilities, a CA-CFAR's ratio stays the ratio.
- ``"ratio"`` (the default; the only choice when the threshold varies from pixel to pixel):
  ``statistic / threshold`` for a positive threshold, so 1 is the design operating point
  for every detector and the peak over an object says by how much its strongest pixel
  exceeds its detector's own threshold. For a threshold ``<= 0`` (a z-score detector at
  ``pfa >= 0.5``) the ratio is meaningless, and ``1 + statistic - threshold`` is used
  instead (still 1 at the threshold, increasing).

Both are strictly increasing maps of each other for a single threshold, so every ranked
metric is the same on either; the candidate pixels (``rules.floor``) are always chosen on
the ratio.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import Tensor

from torchsar._checks import broadcasts, check_choice, check_per_plane, check_real, has_nan
from torchsar.errors import (
    InputTypeError,
    InputValueError,
    OptionError,
    ShapeError,
    WindowSizeError,
)
from torchsar.objects.closing import close_pixels
from torchsar.objects.components import label_pixels
from torchsar.objects.objects import Objects
from torchsar.objects.properties import measure_pixels
from torchsar.objects.rules import ObjectRules

__all__ = ["SCALES", "discriminate", "normalised_score", "own_regions", "single_threshold"]

SCALES = ("ratio", "statistic")


def normalised_score(statistic: Tensor, threshold: Tensor | float) -> Tensor:
    """The detector-independent score: ``statistic / threshold`` (threshold > 0), else
    ``1 + statistic - threshold``; float64, ``-inf`` stays ``-inf``.

    Examples:
        >>> normalised_score(torch.tensor([2.0, 8.0]), torch.tensor(4.0)).tolist()
        [0.5, 2.0]
    """
    s = statistic.to(torch.float64)
    t = torch.as_tensor(threshold, dtype=torch.float64, device=s.device)
    return torch.where(t > 0, s / torch.where(t > 0, t, 1.0), 1.0 + s - t)


def _as_float(threshold: Tensor | float) -> Tensor:
    """``threshold`` as a tensor: a tensor as it is, a Python number in float64 (not
    rounded to float32)."""
    if isinstance(threshold, Tensor):
        return threshold.detach()
    return torch.as_tensor(threshold, dtype=torch.float64)


def single_threshold(threshold: Tensor | float) -> float | None:
    """The threshold's one value when it holds a single finite value (0-dim, or every
    entry equal), else ``None`` (a threshold per pixel or per image, or an infinite one).

    Examples:
        >>> single_threshold(torch.tensor(0.5)), single_threshold(torch.tensor([1.0, 2.0]))
        (0.5, None)
    """
    t = _as_float(threshold).reshape(-1)
    if t.numel() == 0:
        return None
    one = float(t[0])
    if not math.isfinite(one) or (t.numel() > 1 and not bool((t == t[0]).all())):
        return None
    return one


def _scale_threshold(threshold: Tensor | float, scale: str) -> float | None:
    """The operating threshold of the objects on ``scale`` (``None``: the ratio's 1)."""
    check_choice(scale, "scale", SCALES)
    if scale == "ratio":
        return None
    one = single_threshold(threshold)
    if one is None:
        raise OptionError(
            "scale='statistic' needs one finite threshold for the whole batch; "
            "a threshold per pixel or per image is scored with scale='ratio'"
        )
    return one


def own_regions(
    statistic: Tensor, threshold: Tensor | float, labels: Tensor, *, scale: str = "ratio"
) -> Objects:
    """A detector's own regions (``Detection.labels``, ``(B, C, H, W)`` ids, 0 = none) as
    :class:`Objects`, each scored by the peak of its statistic over its pixels on ``scale``
    (``"ratio"``: :func:`normalised_score`, operating threshold 1; ``"statistic"``: the
    statistic itself, operating threshold the single ``threshold``).

    Examples:
        >>> lab = torch.zeros(1, 1, 4, 4, dtype=torch.int64); lab[0, 0, :2, :2] = 3
        >>> o = own_regions(torch.arange(16.0).reshape(1, 1, 4, 4), 2.0, lab)
        >>> o.area.tolist(), o.score.tolist()
        ([4], [2.5])
        >>> own_regions(torch.arange(16.0).reshape(1, 1, 4, 4), 2.0, lab,
        ...             scale="statistic").score.tolist()
        [5.0]
    """
    own = _scale_threshold(threshold, scale)
    b, c, h, w = statistic.shape
    flat = labels.reshape(-1).cpu().numpy()
    idx = np.flatnonzero(flat > 0)
    at = torch.from_numpy(idx)
    stat = statistic.reshape(-1).cpu()[at]
    if own is not None:
        score = stat.to(torch.float64).numpy()
        obj = Objects.from_label_pixels(flat[idx], idx, score, (b * c, h, w))
        return obj.with_threshold(own)
    thr = torch.as_tensor(threshold).cpu()
    if thr.numel() > 1:  # a threshold per pixel or per image: its value at each pixel
        thr = thr.broadcast_to(statistic.shape).reshape(-1)[at]
    score = normalised_score(stat, thr).numpy()
    return Objects.from_label_pixels(flat[idx], idx, score, (b * c, h, w))


def _candidates(
    statistic: Tensor, threshold, floor: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The candidate pixels (flat indices into the ``(N, H, W)`` stack, ascending), their
    float64 ratio scores and their float64 statistics: a loose float32 pre-filter of
    ``score > floor`` (every other pixel's score is at most ``floor``; the exact test is
    left to the caller). NumPy, single threaded: a handful of full-size passes."""
    b, c, h, w = statistic.shape
    stat = statistic.detach().cpu().numpy().reshape(-1)
    thr = _as_float(threshold).cpu().to(torch.float64).numpy()
    if thr.size == 1 and stat.size:  # the usual case: no full-size threshold plane
        one = float(thr.reshape(-1)[0])
        thr = None
    else:
        thr = np.broadcast_to(thr, (b, c, h, w)).reshape(-1)
        one = float(thr[0]) if thr.size and np.all(thr == thr[0]) else None
    if one is not None:
        loose = floor * one * (1 - 1e-5) - 1e-30 if one > 0 else one + floor - 1.0 - 1e-5
        idx = np.flatnonzero(stat >= loose)
        t = np.full(idx.size, one)
    else:
        loose = np.where(thr > 0, floor * thr * (1 - 1e-5) - 1e-30, thr + floor - 1.0 - 1e-5)
        idx = np.flatnonzero(stat >= loose)
        t = thr[idx]
    s = stat[idx].astype(np.float64)
    return idx, normalised_score(torch.from_numpy(s), torch.from_numpy(t)).numpy(), s


def _scores_at(idx: np.ndarray, cand: np.ndarray, score: np.ndarray) -> np.ndarray:
    """The score of each pixel ``idx``: its candidate's (``cand``, ascending), else
    ``-inf`` (pixels the closing added)."""
    pos = np.minimum(np.searchsorted(cand, idx), max(cand.size - 1, 0))
    hit = cand[pos] == idx if cand.size else np.zeros(idx.size, bool)
    return np.where(hit, score[pos] if cand.size else -np.inf, -np.inf)


def _check(
    statistic: object, threshold: object, pixel_area: object, rules: ObjectRules
) -> np.ndarray | None:
    """Validate the arguments; return ``pixel_area`` as one value per plane (or None)."""
    if not isinstance(rules, ObjectRules):
        raise OptionError(f"rules must be an ObjectRules, got {type(rules).__name__}")
    if not isinstance(statistic, Tensor) or not statistic.is_floating_point():
        got = statistic.dtype if isinstance(statistic, Tensor) else type(statistic).__name__
        raise InputTypeError(f"statistic must be a floating torch.Tensor, got {got}")
    if statistic.dim() != 4:
        raise ShapeError(f"statistic must have shape (B, C, H, W), got {tuple(statistic.shape)}")
    if has_nan(statistic):
        raise InputValueError("statistic must not hold NaN values")
    thr = check_real(threshold, "threshold")
    if not broadcasts(thr.shape, statistic.shape):
        raise ShapeError(
            f"threshold must broadcast to statistic {tuple(statistic.shape)}, "
            f"got {tuple(thr.shape)}"
        )
    h, w = statistic.shape[-2:]
    if h * w and rules.closing > max(h, w):
        raise WindowSizeError(
            f"closing radius {rules.closing} is larger than the image ({h}x{w}); "
            f"use closing <= {max(h, w)}"
        )
    if rules.units == "m2" and pixel_area is None:
        raise OptionError("object areas in m2 need the pixel spacing: pass pixel_area")
    planes = statistic.shape[0] * statistic.shape[1]
    return None if pixel_area is None else check_per_plane(pixel_area, "pixel_area", planes)


def _keep(area: np.ndarray, plane: np.ndarray, rules: ObjectRules, pixel_area) -> np.ndarray:
    """Objects within ``[min_area, max_area]`` (pixels, or m^2 via each plane's pixel area,
    ``pixel_area`` one value per plane)."""
    size = area.astype(np.float64)
    if rules.units == "m2":
        size = size * pixel_area[plane]
    keep = size >= rules.min_area
    if rules.max_area is not None:
        keep &= size <= rules.max_area
    return keep


def discriminate(
    statistic: Tensor,
    threshold: Tensor | float,
    *,
    rules: ObjectRules | None = None,
    pixel_area: np.ndarray | float | None = None,
    scale: str = "ratio",
) -> Objects:
    """Turn a detector's statistic into scored objects (see the module docstring).

    Args:
        statistic: float ``(B, C, H, W)``, the detector's ``Detection.statistic``
            (``-inf`` allowed for untestable pixels, NaN refused).
        threshold: the design threshold, broadcastable to ``statistic`` (``±inf`` allowed,
            NaN refused).
        rules: closing, size and connectivity rules (default :class:`ObjectRules`); the
            closing radius may not exceed the image's larger side.
        pixel_area: square metres per pixel (finite, > 0), a scalar used for every plane
            or one value per plane (``B * C``); needed when ``rules.units == "m2"``.
        scale: the objects' scores: ``"ratio"`` (statistic / threshold, operating threshold
            1) or ``"statistic"`` (the statistic's own values, operating threshold the
            single ``threshold``); the objects are the same on both.

    Returns:
        :class:`Objects` in id order (planes in order, then label order).

    Raises:
        InputTypeError, ShapeError, InputValueError: bad ``statistic``, ``threshold`` or
            ``pixel_area``.
        WindowSizeError: ``rules.closing`` larger than the image.
        OptionError: areas in m^2 without ``pixel_area``; an unknown ``scale``, or
            ``"statistic"`` with a threshold that varies over the batch.

    Examples:
        >>> s = torch.zeros(1, 1, 8, 8); s[0, 0, 1:3, 1:3] = 5.0; s[0, 0, 6, 6] = 3.0
        >>> o = discriminate(s, 2.0, rules=ObjectRules(min_area=2))
        >>> len(o), o.area.tolist(), o.score.tolist()
        (1, [4], [2.5])
        >>> o = discriminate(s, 2.0, rules=ObjectRules(min_area=2), scale="statistic")
        >>> o.score.tolist(), o.threshold
        ([5.0], 2.0)
    """
    rules = ObjectRules() if rules is None else rules
    pixel_area = _check(statistic, threshold, pixel_area, rules)
    own = _scale_threshold(threshold, scale)
    b, c = statistic.shape[:2]
    h, w = statistic.shape[-2:]
    shape = (b * c, h, w)
    cand, score, raw = _candidates(statistic, threshold, rules.floor)
    idx = close_pixels(cand[score > rules.floor], shape, rules.closing)
    labels, n, lab = label_pixels(idx, shape, 2 if rules.connectivity == 8 else 1)
    peak = _scores_at(idx, cand, score if own is None else raw)
    props = measure_pixels(lab, idx, (h, w), n, peak)
    keep = _keep(props["area"], props["plane"], rules, pixel_area)
    if not keep.all():
        labels, lab, idx = _renumber(keep, lab, idx, shape)
    obj = Objects(
        labels=labels,
        **{k: v[keep] for k, v in props.items()},
        planes=b * c,
        shape=(h, w),
        threshold=1.0 if own is None else own,
    )
    return obj.with_pixel_lists(lab - 1, idx)


def _renumber(keep: np.ndarray, lab: np.ndarray, idx: np.ndarray, shape):
    """The label stack of the kept objects ``keep`` (numbered ``1..`` in order) and their
    pixels ``(lab, idx)``."""
    lut = np.zeros(keep.size + 1, dtype=np.int64)
    lut[1:][keep] = np.arange(1, int(keep.sum()) + 1)
    new = lut[lab]
    on = new > 0
    labels = np.zeros(int(np.prod(shape)), np.int32)
    labels[idx[on]] = new[on]
    return labels.reshape(shape), new[on], idx[on]
