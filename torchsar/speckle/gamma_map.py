"""Gamma-MAP speckle filter (Lopes et al. 1990)."""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar.speckle._local import Speckle, filter_intensity, prepare

__all__ = ["gamma_map"]


def _map_estimate(i: Tensor, mu: Tensor, ci2: Tensor, sp: Speckle) -> Tensor:
    """The MAP reflectivity ``(b mu + sqrt(b^2 mu^2 + 4 a L mu I)) / (2a)`` with
    ``a = (1 + Cu^2) / (Ci^2 - Cu^2)``, ``b = a - L - 1``, for ``Cu^2 < Ci^2 <= Cmax^2``
    (other pixels get finite filler values). For ``b < 0`` it is evaluated as
    ``2 L mu I / (sqrt(D) - b mu)`` (same value, no cancellation)."""
    L = sp.looks
    excess = (ci2 - sp.cu2).clamp_min(torch.finfo(ci2.dtype).tiny)
    a = (1.0 + sp.cu2) / excess
    b = a - L - 1.0
    root = torch.sqrt((b * mu).square() + 4.0 * a * L * mu * i)
    plus = (b * mu + root) / (2.0 * a)
    den = root - b * mu
    minus = 2.0 * L * mu * i / torch.where(den > 0, den, torch.ones_like(den))
    return torch.where(b >= 0, plus, minus)


def _textured(i: Tensor, mu: Tensor, ci2: Tensor, sp: Speckle) -> tuple[Tensor, Tensor, Tensor]:
    """The inputs of :func:`_map_estimate`; under autograd, pixels outside the textured band
    (whose estimate is discarded) get harmless values, so no NaN gradient leaks through
    ``torch.where``."""
    if not (i.requires_grad or mu.requires_grad):
        return i, mu, ci2
    band = (ci2 > sp.cu2) & (ci2 < sp.cmax2)
    mid = 0.5 * (sp.cu2 + sp.cmax2)
    return torch.where(band, i, 1.0), torch.where(band, mu, 1.0), torch.where(band, ci2, mid)


def gamma_map(x: Tensor, *, window: int = 5, looks: float = 1.0, amplitude: bool = False) -> Tensor:
    """Gamma-MAP filter: maximum a posteriori reflectivity under a gamma prior.

    ``Ci <= Cu``: ``mu``; ``Ci >= Cmax``: ``I``; otherwise
    ``(b mu + sqrt(b^2 mu^2 + 4 a L mu I)) / (2 a)``, ``a = (1 + Cu^2) / (Ci^2 - Cu^2)``,
    ``b = a - L - 1`` (Lopes et al. 1990). Window statistics and border rule as in
    :func:`~torchsar.speckle.lee`.

    Args:
        x: intensity ``(B, C, H, W)`` (amplitude with ``amplitude=True``).
        window: odd window side, >= 3.
        looks: number of looks L.
        amplitude: amplitude in and out.

    Returns:
        The filtered image (float64 for float64 input, else float32).

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        A. Lopes, E. Nezry, R. Touzi, H. Laur, "Maximum a posteriori speckle filtering and
        first order texture models in SAR images", IGARSS 1990,
        doi:10.1109/IGARSS.1990.688742.

    Examples:
        >>> x = torch.full((1, 1, 8, 8), 2.0)
        >>> gamma_map(x, window=3).unique().tolist()
        [2.0]
    """
    req = prepare(x, window, looks, amplitude)
    sp = req.speckle

    def formula(i: Tensor, mu: Tensor, ci2: Tensor) -> Tensor:
        out = torch.where(ci2 <= sp.cu2, mu, _map_estimate(*_textured(i, mu, ci2, sp), sp))
        return torch.where(ci2 >= sp.cmax2, i, out)

    return filter_intensity(req, formula)
