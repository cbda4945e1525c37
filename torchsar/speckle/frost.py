"""Frost and enhanced Frost filters: local means weighted by ``exp(-decay * d)``.

``d`` is the Euclidean distance (pixels) of a window cell to the centre pixel and ``decay``
is per pixel, driven by the local coefficient of variation ``Ci``. The weighted means are
exact and computed by distance shells (:func:`torchsar.windows.exp_distance_mean`): no
per-pixel kernels, memory linear in the image, ``(w + 1)^2 / 4`` additions and one ``exp`` per
distance shell per pixel.

Border rule: ``mu`` and ``Ci`` over the in-image window cells (as every speckle filter), and
the weighted mean over the in-image cells, normalised by the sum of their weights. Interior
pixels are exact.

Enhanced Frost's three classes are the limits of one weighted mean: ``decay = 0`` gives the
window mean ``mu`` (``Ci <= Cu``) and ``decay = inf`` gives the centre pixel ``I``
(``Ci >= Cmax``), so the whole filter is one distance-shell pass.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

from torch import Tensor

from torchsar.speckle._local import Request, decay_map, finish, prepare, scratch
from torchsar.windows import exp_distance_mean

__all__ = ["enhanced_frost", "frost"]


def frost(
    x: Tensor,
    *,
    window: int = 5,
    looks: float = 1.0,
    damping: float = 2.0,
    amplitude: bool = False,
) -> Tensor:
    """Frost filter: weighted window mean with weights ``exp(-damping Ci^2 d)``.

    Args:
        x: intensity ``(B, C, H, W)`` (amplitude with ``amplitude=True``).
        window: odd window side, >= 3.
        looks: number of looks L (accepted for a uniform signature; the Frost weights do
            not depend on it).
        damping: damping factor K (>= 0); 0 gives the box mean.
        amplitude: amplitude in and out (squared before, square-rooted after).

    Returns:
        The filtered image (float64 for float64 input, else float32).

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        V. S. Frost, J. A. Stiles, K. S. Shanmugan, J. C. Holtzman, "A model for radar
        images and its application to adaptive digital filtering of multiplicative noise",
        IEEE TPAMI 4(2), 1982, doi:10.1109/TPAMI.1982.4767223.

    Examples:
        >>> x = torch.full((1, 1, 8, 8), 5.0)
        >>> frost(x, window=3).unique().tolist()
        [5.0]
    """
    req = prepare(x, window, looks, amplitude, damping)
    return _distance_weighted(req, lambda ci2: scratch(ci2).mul_(req.damping))


def _distance_weighted(req: Request, decay: Callable[[Tensor], Tensor]) -> Tensor:
    """The Frost-type mean: window cells weighted by ``exp(-decay(Ci^2) d)``."""
    return finish(req, exp_distance_mean(req.intensity, req.radius, decay_map(req, decay)))


def enhanced_frost(
    x: Tensor,
    *,
    window: int = 5,
    looks: float = 1.0,
    damping: float = 1.0,
    amplitude: bool = False,
) -> Tensor:
    """Enhanced Frost filter (Lopes et al. 1990), the seed paper's despeckling step.

    ``Ci <= Cu`` (homogeneous): window mean ``mu``; ``Ci >= Cmax`` (point target): ``I``;
    otherwise the window mean weighted by ``exp(-damping (Ci - Cu) / (Cmax - Ci) d)``, with
    ``Cu = 1/sqrt(L)``, ``Cmax = sqrt(1 + 2/L)`` and ``d`` the distance to the centre pixel.

    Args:
        x: intensity ``(B, C, H, W)`` (amplitude with ``amplitude=True``).
        window: odd window side, >= 3.
        looks: number of looks L.
        damping: damping factor (>= 0).
        amplitude: amplitude in and out.

    Returns:
        The filtered image (float64 for float64 input, else float32).

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        A. Lopes, R. Touzi, E. Nezry, "Adaptive speckle filters and scene heterogeneity",
        IEEE TGRS 28(6), 1990, doi:10.1109/36.62623.

    Examples:
        >>> x = torch.ones(1, 1, 9, 9); x[0, 0, 4, 4] = 100.0
        >>> enhanced_frost(x, window=3)[0, 0, 4, 4].item()  # a point target is kept
        100.0
    """
    req = prepare(x, window, looks, amplitude, damping)
    return _distance_weighted(req, partial(req.speckle.heterogeneity, damping=req.damping))
