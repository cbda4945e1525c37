"""Per-item power-of-two normalisation of complex data, so that the imaging and autofocus
methods give the same result, scaled, for data of any magnitude.

Dividing by a power of two is exact in floating point (no rounding, barring underflow
below the smallest subnormal), so a method run on ``g / scale`` and scaled back computes
what it computes on ``g`` while its squares and sums stay far from overflow (a complex64
phase history of amplitude 1e20 has squared magnitudes beyond float32's range).
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["unit_scale"]


def unit_scale(g: Tensor) -> Tensor:
    """Per-item power of two ``(B,)`` (``g``'s real dtype) that brings the largest real or
    imaginary part of item ``b`` of the complex ``g (B, ...)`` into ``[1, 2)``; 1 for an
    all-zero item.

    Example:
        >>> g = torch.tensor([[3.0 + 0j], [0j], [0.1j]])
        >>> unit_scale(g).tolist()
        [2.0, 1.0, 0.0625]
    """
    real = g.real.dtype
    b = g.shape[0]
    if g.numel() == 0:
        return torch.ones(b, dtype=real, device=g.device)
    peak = torch.view_as_real(g).abs().reshape(b, -1).amax(1)
    _, exponent = torch.frexp(peak)  # peak = mantissa * 2**exponent, mantissa in [0.5, 1)
    scale = torch.ldexp(torch.ones_like(peak), exponent - 1)
    return torch.where(peak > 0, scale, torch.ones_like(peak))
