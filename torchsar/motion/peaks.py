"""Point-target detection in (subpatch) images: CFAR mask + local-maximum suppression."""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial

import torch
from torch import Tensor

from torchsar._checks import check_image, check_int
from torchsar.cfar import Detection, ca

__all__ = ["default_detector", "detect_peaks", "intensity", "window_max"]


def default_detector(
    resolution_px: tuple[float, float], *, pfa: float = 1e-6
) -> Callable[[Tensor], Detection]:
    """Cell-averaging CFAR sized to the impulse response.

    The guard box (``guard = ceil(3 * max resolution in pixels)``) holds the main lobe and
    near sidelobes of a point target; the training band has the same width.

    Args:
        resolution_px: ``(range, azimuth)`` resolution in pixels.
        pfa: design false-alarm probability per pixel.

    Examples:
        >>> d = default_detector((2.0, 1.0))
        >>> d(torch.ones(1, 1, 40, 40)).mask.any().item()
        False
    """
    guard = max(1, math.ceil(3 * max(resolution_px)))
    return partial(ca, guard=guard, train=guard, pfa=pfa)


def detect_peaks(
    intensity: Tensor,
    *,
    detector: Callable[[Tensor], Detection],
    radius: int = 8,
) -> Tensor:
    """Pixels that are CFAR detections and the maximum of their ``(2 radius + 1)^2`` window.

    One pixel per point target (its peak); sidelobes and the rest of the main lobe are
    suppressed because a brighter pixel lies within ``radius``. Border windows wrap around
    (formed images are periodic).

    Args:
        intensity: ``(B, C, H, W)`` non-negative intensity.
        detector: ``x -> Detection`` (e.g. :func:`default_detector` or a partial of any
            :mod:`torchsar.cfar` detector).
        radius: suppression half-width in pixels (>= 0).

    Returns:
        bool ``(B, C, H, W)`` peak mask.

    Examples:
        >>> x = torch.ones(1, 1, 32, 32); x[0, 0, 10, 12] = 1e4; x[0, 0, 10, 13] = 5e3
        >>> det = default_detector((1.0, 1.0), pfa=1e-3)
        >>> detect_peaks(x, detector=det, radius=2).nonzero().tolist()
        [[0, 0, 10, 12]]
    """
    check_image(intensity, "intensity")
    r = check_int(radius, "radius", minimum=0)
    mask = detector(intensity).mask
    if r == 0 or intensity.numel() == 0:
        return mask
    b, c, h, w = intensity.shape
    flat = intensity.reshape(b * c, 1, h, w)
    return mask & (flat == window_max(flat, r)).reshape(b, c, h, w)


def intensity(x: Tensor) -> Tensor:
    """``|x|^2`` of a complex tensor without the square root of ``abs``."""
    return x.real.square() + x.imag.square()


def window_max(x: Tensor, r: int) -> Tensor:
    """Maximum over the ``(2r+1)^2`` window with circular borders (separable, doubling).

    Examples:
        >>> x = torch.zeros(1, 1, 5, 7); x[0, 0, 2, 3] = 1.0
        >>> window_max(x, 1)[0, 0, :, 3].tolist(), window_max(x, 1)[0, 0, 2].tolist()
        ([0.0, 1.0, 1.0, 1.0, 0.0], [0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 0.0])
    """
    return _run_max(_run_max(x, r, -1), r, -2)


def _run_max(x: Tensor, r: int, dim: int) -> Tensor:
    """Circular running maximum over ``[i - r, i + r]`` along ``dim`` in ``O(log r)`` passes."""
    k = 2 * r + 1
    m, span = x, 1
    while 2 * span <= k:
        m = torch.maximum(m, torch.roll(m, -span, dim))
        span *= 2
    return torch.roll(torch.maximum(m, torch.roll(m, span - k, dim)), r, dim)
