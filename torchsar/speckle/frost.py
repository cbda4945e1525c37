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

import math
from collections.abc import Callable
from functools import lru_cache, partial

import numpy as np
from torch import Tensor

from torchsar.speckle._local import (
    Request,
    decay_map,
    finish,
    prepare,
    run_kernel,
    scratch,
    takes_kernel,
)
from torchsar.windows import distance_shells, exp_distance_mean

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
    req = prepare(x, window, looks, amplitude, damping, kernel=True)
    return _distance_weighted(req, lambda ci2: scratch(ci2).mul_(req.damping))


def _distance_weighted(
    req: Request, decay: Callable[[Tensor], Tensor], *, enhanced: bool = False
) -> Tensor:
    """The Frost-type mean: window cells weighted by ``exp(-decay(Ci^2) d)``. CPU tensors
    without gradients take the one-sweep kernel (:mod:`torchsar._shell_kernels`: the same
    decay, as ``enhanced`` says, and weights in float64, cast once)."""
    x = req.intensity
    if takes_kernel(x):
        return finish(req, _compiled(req, enhanced), nonnegative=True)
    return finish(req, exp_distance_mean(x, req.radius, decay_map(req, decay)))


def _compiled(req: Request, enhanced: bool) -> Tensor:
    from torchsar import _shell_kernels

    shells, dist = _shell_table(req.radius)
    powers = _power_table(req.radius)
    sp = req.speckle
    return run_kernel(
        req,
        lambda planes, out: _shell_kernels.frost_filter(
            planes,
            req.radius,
            shells,
            dist,
            powers,
            enhanced,
            req.damping,
            sp.cu2,
            sp.cmax2,
            out,
        ),
    )


@lru_cache(maxsize=16)
def _shell_table(radius: int) -> tuple[np.ndarray, np.ndarray]:
    """The orbits ``(shell, p, q)`` of the non-zero distance shells of the window and the
    shells' distances (:func:`torchsar.windows.distance_shells`)."""
    shells = distance_shells(radius)[1:]  # the centre (distance 0) has weight 1
    rows = [(k, p, q) for k, (_, orbits) in enumerate(shells) for p, q in orbits]
    dist = np.array([d2**0.5 for d2, _ in shells])
    return np.array(rows, dtype=np.int64).reshape(-1, 3), dist


@lru_cache(maxsize=16)
def _power_table(radius: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each shell's distance as ``m sqrt(s)``, ``s`` square-free: the distinct ``sqrt(s)``
    (``bases``), and per shell the index of its base and its ``m``. The kernel evaluates
    one ``exp`` per base and forms the weight of ``m sqrt(s)`` as the ``m``-th power (the
    shells of a base come in increasing ``m``)."""
    shells = distance_shells(radius)[1:]
    roots: dict[int, int] = {}
    base_of, multiple = [], []
    for d2, _ in shells:
        m = max(k for k in range(1, math.isqrt(d2) + 1) if d2 % (k * k) == 0)
        base_of.append(roots.setdefault(d2 // (m * m), len(roots)))
        multiple.append(m)
    bases = np.array([s**0.5 for s in roots])
    return bases, np.array(base_of, dtype=np.int64), np.array(multiple, dtype=np.int64)


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
    req = prepare(x, window, looks, amplitude, damping, kernel=True)
    return _distance_weighted(
        req, partial(req.speckle.heterogeneity, damping=req.damping), enhanced=True
    )
