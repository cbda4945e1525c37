"""Power-of-two normalisation, so that scale-free computations work on data of any
magnitude.

Dividing by a power of two is exact in floating point (no rounding, barring underflow
below the smallest subnormal), so a method run on ``x / scale`` and scaled back computes
what it computes on ``x`` while its squares and sums stay far from overflow (a complex64
phase history of amplitude 1e20 has squared magnitudes beyond float32's range).
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["power_of_two", "unit_scale"]


def power_of_two(peak: Tensor) -> Tensor:
    """The power of two that brings each non-negative ``peak`` into ``[1, 2)`` (1 where
    ``peak`` is 0), same shape and dtype.

    Examples:
        >>> power_of_two(torch.tensor([3.0, 0.0, 0.1])).tolist()
        [2.0, 1.0, 0.0625]
    """
    _, exponent = torch.frexp(peak)  # peak = mantissa * 2**exponent, mantissa in [0.5, 1)
    return torch.where(peak > 0, torch.ldexp(torch.ones_like(peak), exponent - 1), 1.0)


def unit_scale(x: Tensor, dims: int | None = None) -> Tensor:
    """Per-item :func:`power_of_two` of the largest magnitude (for complex ``x``: the
    largest real or imaginary part) over the last ``dims`` dims (default: all but the
    first), in ``x``'s real dtype, with the reduced dims kept as size 1.

    Examples:
        >>> g = torch.tensor([[3.0 + 0j], [0j], [0.1j]])
        >>> unit_scale(g).flatten().tolist()
        [2.0, 1.0, 0.0625]
    """
    dims = x.dim() - 1 if dims is None else dims
    lead = x.shape[: x.dim() - dims]
    real = x.real.dtype if x.is_complex() else x.dtype
    if x.numel() == 0:
        return torch.ones(*lead, *([1] * dims), dtype=real, device=x.device)
    mag = torch.view_as_real(x).abs().amax(-1) if x.is_complex() else x.abs()
    peak = mag.detach().reshape(*lead, -1).amax(-1)
    return power_of_two(peak).reshape(*lead, *([1] * dims))
