"""Lee, Kuan and enhanced Lee filters: ``R = mu + W (I - mu)`` with an adaptive weight ``W``.

The three filters differ only in how the weight is computed from the local coefficient of
variation ``Ci``; the window statistics and the border rule are those of
:mod:`torchsar.speckle._local`.
"""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar.speckle._local import Compiled, filter_intensity, prepare, scratch

__all__ = ["enhanced_lee", "kuan", "lee"]


def _mmse_weight(ci2: Tensor, cu2: float, scale: float) -> Tensor:
    """``clip((1 - Cu^2 / Ci^2) / scale, 0, 1)``; ``Ci = 0`` gives ``-inf`` clipped to 0
    (under autograd ``Ci^2`` is floored at the smallest normal float instead: same value,
    finite gradient)."""
    if ci2.requires_grad:
        ci2 = ci2.clamp_min(torch.finfo(ci2.dtype).tiny)
    return scratch(ci2.reciprocal()).mul_(-cu2).add_(1.0).div_(scale).clamp_(0.0, 1.0)


def _mmse(x: Tensor, window: int, looks: float, amplitude: bool, *, kuan: bool) -> Tensor:
    """``R = mu + W (I - mu)`` with the Lee weight, or Kuan's (divided by ``1 + Cu^2``)."""
    req = prepare(x, window, looks, amplitude, kernel=True)
    cu2 = req.speckle.cu2
    scale = 1.0 + cu2 if kuan else 1.0
    return filter_intensity(
        req,
        lambda i, mu, ci2: torch.lerp(mu, i, _mmse_weight(ci2, cu2, scale)),
        Compiled(False, cu2, weight_scale=scale),
    )


def lee(x: Tensor, *, window: int = 5, looks: float = 1.0, amplitude: bool = False) -> Tensor:
    """Lee filter: ``R = mu + W (I - mu)``, ``W = clip(1 - Cu^2 / Ci^2, 0, 1)``.

    ``mu`` and ``Ci = sigma / mu`` are the mean and coefficient of variation (population
    standard deviation) over the ``window x window`` box; ``Cu = 1 / sqrt(looks)``. Border
    pixels use the window cells inside the image; interior pixels are exact.

    Args:
        x: intensity ``(B, C, H, W)``, non-negative and finite (amplitude with
            ``amplitude=True``).
        window: odd window side, >= 3 and no larger than the image.
        looks: number of looks L of the speckle.
        amplitude: ``x`` is amplitude: it is squared before filtering and the result is
            square-rooted back to amplitude.

    Returns:
        The filtered image, same shape, dtype float64 for float64 input, else float32.

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        J.-S. Lee, "Digital image enhancement and noise filtering by use of local
        statistics", IEEE TPAMI 2(2), 1980, doi:10.1109/TPAMI.1980.4766994.

    Examples:
        >>> x = torch.full((1, 1, 8, 8), 3.0)
        >>> lee(x, window=3).unique().tolist()
        [3.0]
    """
    return _mmse(x, window, looks, amplitude, kuan=False)


def kuan(x: Tensor, *, window: int = 5, looks: float = 1.0, amplitude: bool = False) -> Tensor:
    """Kuan filter: ``R = mu + W (I - mu)``, ``W = clip((1 - Cu^2/Ci^2) / (1 + Cu^2), 0, 1)``.

    Same window statistics, border rule and arguments as :func:`lee`.

    Args:
        x: intensity ``(B, C, H, W)`` (amplitude with ``amplitude=True``).
        window: odd window side, >= 3.
        looks: number of looks L.
        amplitude: amplitude in and out (squared before, square-rooted after).

    Returns:
        The filtered image (float64 for float64 input, else float32).

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        D. T. Kuan, A. A. Sawchuk, T. C. Strand, P. Chavel, "Adaptive noise smoothing filter
        for images with signal-dependent noise", IEEE TPAMI 7(2), 1985,
        doi:10.1109/TPAMI.1985.4767641.

    Examples:
        >>> x = torch.zeros(1, 1, 8, 8)
        >>> kuan(x, window=3).abs().max().item()
        0.0
    """
    return _mmse(x, window, looks, amplitude, kuan=True)


def enhanced_lee(
    x: Tensor,
    *,
    window: int = 5,
    looks: float = 1.0,
    damping: float = 1.0,
    amplitude: bool = False,
) -> Tensor:
    """Enhanced Lee filter (Lopes et al. 1990): three classes by ``Ci``.

    ``Ci <= Cu`` (homogeneous): ``mu``; ``Ci >= Cmax`` (point target): ``I``; otherwise
    ``mu W + I (1 - W)`` with ``W = exp(-damping (Ci - Cu) / (Cmax - Ci))``,
    ``Cu = 1/sqrt(L)``, ``Cmax = sqrt(1 + 2/L)``.

    Args:
        x: intensity ``(B, C, H, W)`` (amplitude with ``amplitude=True``).
        window: odd window side, >= 3.
        looks: number of looks L.
        damping: damping factor (>= 0); larger keeps more of the observation.
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
        >>> enhanced_lee(x, window=3)[0, 0, 4, 4].item()  # a point target is kept
        100.0
    """
    req = prepare(x, window, looks, amplitude, damping, kernel=True)
    sp, k = req.speckle, req.damping

    def formula(i: Tensor, mu: Tensor, ci2: Tensor) -> Tensor:
        return torch.lerp(i, mu, sp.heterogeneity(ci2, k).neg_().exp_())

    return filter_intensity(req, formula, Compiled(True, sp.cu2, damping=k, cmax2=sp.cmax2))
