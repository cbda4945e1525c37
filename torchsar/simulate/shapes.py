"""Rasterising rotated rectangles and radar shadows on pixel grids.

Pixel ``(r, c)`` has its centre at coordinates ``(r, c)``; a shape covers a pixel when the
pixel centre lies inside it (closed boundary). Rows are the range axis: the radar is above
the image (near range = row 0), so shadows fall towards increasing rows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["Box", "RotatedRect", "sweep_down"]

Box = tuple[int, int, int, int]
"""``(r0, c0, r1, c1)``: rows ``r0:r1`` and columns ``c0:c1`` (end-exclusive)."""


@dataclass(frozen=True)
class RotatedRect:
    """A rectangle centred at ``(row, col)`` with its long axis at ``heading`` radians.

    ``heading`` is measured from the +column axis towards the +row axis; local coordinates
    are ``u`` along the long axis (``|u| <= length / 2``) and ``v`` across it
    (``|v| <= width / 2``).
    """

    row: float
    col: float
    length: float
    width: float
    heading: float

    def half_extent(self) -> tuple[float, float]:
        """Half-extents ``(rows, cols)`` of the axis-aligned bounding box."""
        c, s = abs(math.cos(self.heading)), abs(math.sin(self.heading))
        return 0.5 * (self.length * s + self.width * c), 0.5 * (self.length * c + self.width * s)

    def box(self, height: int, width: int) -> Box:
        """Bounding box of the covered pixels, clipped to a ``height x width`` image."""
        hr, hc = self.half_extent()
        r0, c0 = max(0, math.ceil(self.row - hr)), max(0, math.ceil(self.col - hc))
        r1 = min(height, math.floor(self.row + hr) + 1)
        c1 = min(width, math.floor(self.col + hc) + 1)
        return r0, c0, max(r0, r1), max(c0, c1)

    def inside_image(self, height: int, width: int, margin: float = 0.0) -> bool:
        """True when the whole rectangle lies ``margin`` pixels inside the image."""
        hr, hc = self.half_extent()
        return (
            self.row - hr >= margin
            and self.col - hc >= margin
            and self.row + hr <= height - 1 - margin
            and self.col + hc <= width - 1 - margin
        )

    def local(self, box: Box, device: torch.device) -> tuple[Tensor, Tensor]:
        """Local coordinates ``(u, v)`` of the pixel centres in ``box``, each ``(h, w)``."""
        r0, c0, r1, c1 = box
        rows = torch.arange(r0, r1, device=device, dtype=torch.float32) - self.row
        cols = torch.arange(c0, c1, device=device, dtype=torch.float32) - self.col
        c, s = math.cos(self.heading), math.sin(self.heading)
        dr, dc = rows[:, None], cols[None, :]
        return dc * c + dr * s, dr * c - dc * s

    def covers(self, u: Tensor, v: Tensor) -> Tensor:
        """Boolean mask of the local coordinates inside the rectangle."""
        return (u.abs() <= 0.5 * self.length) & (v.abs() <= 0.5 * self.width)


def sweep_down(mask: Tensor, length: int) -> Tensor:
    """Pixels that have a ``mask`` pixel at most ``length`` rows above them (same column).

    This is the mask smeared ``length`` pixels towards far range; ``sweep_down(m, L) & ~m``
    is the radar shadow of a convex object. Vectorised with a cumulative sum along rows.

    Args:
        mask: bool ``(h, w)``.
        length: sweep length in pixels, >= 0.

    Returns:
        bool ``(h, w)``.

    Examples:
        >>> m = torch.zeros(5, 1, dtype=torch.bool); m[1] = True
        >>> sweep_down(m, 2).flatten().tolist()
        [False, True, True, True, False]
    """
    c = torch.cumsum(mask.to(torch.int32), dim=0)
    shifted = torch.zeros_like(c)
    if length + 1 < c.shape[0]:
        shifted[length + 1 :] = c[: c.shape[0] - length - 1]
    return (c - shifted) > 0
