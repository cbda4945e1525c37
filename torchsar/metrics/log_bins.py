"""Exact bucket indices on the symmetric log grid of :func:`~torchsar.metrics.default_pixel_grid`.

``torch.bucketize`` runs a binary search per value, which dominated the pixel-ROC update on
chips. On the symmetric log grid the bucket follows from ``log10 |x|`` in a few elementwise
operations. Only values within rounding distance of a grid value can land in the wrong
bucket; those few go through the exact binary search (0 and the infinities are exact by the
arithmetic itself). The result equals ``torch.bucketize(x, grid)`` for every finite or
infinite value (tested against it, grid values and their float neighbours included).
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["LogGrid"]


class LogGrid:
    """The grid ``-10^6 .. -10^-3, 0, 10^-3 .. 10^6`` with ``ppd`` points per decade.

    Args:
        ppd: points per decade.
        low: decimal exponent of the smallest positive grid value.
        decades: number of decades covered by the positive half.
    """

    def __init__(self, ppd: int, low: int = -3, decades: int = 9) -> None:
        self.ppd, self.low = ppd, low
        self.m = decades * ppd + 1  # grid values on each side of 0
        pos = torch.logspace(low, low + decades, self.m, dtype=torch.float64)
        self.grid = torch.cat([-pos.flip(0), torch.zeros(1, dtype=torch.float64), pos])

    @classmethod
    def matching(cls, grid: Tensor) -> LogGrid | None:
        """The :class:`LogGrid` equal to ``grid`` (float64), or ``None`` when it is another
        grid."""
        half = (grid.numel() - 1) // 2 - 1
        if half <= 0 or half % 9:
            return None
        log_grid = cls(half // 9)
        same = log_grid.grid.shape == grid.shape and torch.equal(log_grid.grid, grid)
        return log_grid if same else None

    def bucketize(self, x: Tensor, grid: Tensor) -> Tensor:
        """``torch.bucketize(x, grid)`` (``grid``: this grid in ``x``'s dtype and device):
        the number of grid values strictly below each ``x`` (``x`` free of NaN)."""
        a = torch.log10(x.abs()).sub_(self.low).mul_(self.ppd)  # position among |grid| > 0
        k = a.ceil().clamp_(0, self.m)  # positive grid values below |x|, off a grid value
        # x > 0: the m negatives, 0 and k positives lie below; x < 0: m - k negatives do.
        # Exact as it stands for 0 (k = 0, sign 0: m) and +-inf (k = m: 2m + 1 or 0).
        bins = torch.sign(x).mul_(k.add_(0.5)).add_(self.m + 0.5).long()
        # values within rounding of a grid value: the exact search (for 0 and +-inf the
        # distance is NaN, so they stay out)
        unsure = a.sub_(a.round()).abs_().lt_(_SURE).view(-1).nonzero().squeeze(1)
        if unsure.numel():
            flat = bins.view(-1)
            flat[unsure] = torch.bucketize(x.reshape(-1)[unsure], grid)
        return bins


# Distance in grid steps from the nearest grid value beyond which the estimate is exact: the
# logarithm's rounding error in grid steps is below 1e-3 for every float32 and float64 value.
_SURE = 1e-2
