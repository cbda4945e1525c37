"""Window geometry and fast box / ring / block sums (our ``filter2d``).

Every local statistic in torchsar (CFAR rings, pinwheel blocks, speckle-filter boxes) goes
through :func:`rect_sums`: sums of ``x`` (and optionally ``x**2``) over a rectangle placed at
fixed offsets from each pixel, read from a zero-padded float64 integral image with four
shifted slices. The cost per pixel is independent of the window size.

Borders and no-data: cells outside the image never count, and an optional boolean ``valid``
mask removes no-data cells too. Every sum comes with the matching **count** of valid cells,
so a statistic near the border is the textbook statistic over the cells that exist. Interior
pixels (window fully inside, all valid) equal the textbook definition exactly.

Precision: sums are accumulated in float64 after subtracting a per-image offset (the image
mean), so variances of bright, nearly constant areas do not suffer from cancellation, and
a constant image gives exactly zero variance.

Geometry (DESIGN §4.1): ``guard`` g is the half-width of the guard box (``(2g+1)^2`` cells,
CUT included, excluded from training); ``train`` t is the width of the training band; the
outer box is ``(2(g+t)+1)^2`` and the ring holds ``N = (2(g+t)+1)^2 - (2g+1)^2`` cells. The
pinwheel split cuts the ring into 4 equal blocks of ``t x (2g+t+1)`` cells: top, right,
bottom, left.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor

from torchsar._checks import check_int, check_window_fits

__all__ = [
    "Rect",
    "Ring",
    "Sums",
    "box_sums",
    "pinwheel_rects",
    "rect_sums",
    "ring_sums",
]


@dataclass(frozen=True)
class Rect:
    """A rectangle of cells at offsets ``[r0, r1] x [c0, c1]`` (inclusive) from the pixel."""

    r0: int
    r1: int
    c0: int
    c1: int

    @property
    def area(self) -> int:
        """Number of cells in the rectangle."""
        return (self.r1 - self.r0 + 1) * (self.c1 - self.c0 + 1)

    @staticmethod
    def box(radius: int) -> Rect:
        """The centred square of side ``2 * radius + 1``."""
        return Rect(-radius, radius, -radius, radius)


@dataclass(frozen=True)
class Ring:
    """CFAR ring geometry: guard half-width ``guard`` and training-band width ``train``."""

    guard: int
    train: int

    def __post_init__(self) -> None:
        check_int(self.guard, "guard", minimum=0)
        check_int(self.train, "train", minimum=1)

    @property
    def outer(self) -> int:
        """Half-width of the outer box, ``guard + train``."""
        return self.guard + self.train

    @property
    def extent(self) -> int:
        """Full side of the outer box, ``2 * (guard + train) + 1``."""
        return 2 * self.outer + 1

    @property
    def n(self) -> int:
        """Number of training cells, ``(2(g+t)+1)^2 - (2g+1)^2``."""
        return self.extent**2 - (2 * self.guard + 1) ** 2

    def check_fits(self, x: Tensor) -> None:
        """Raise :class:`~torchsar._checks.WindowSizeError` if the ring exceeds ``x``."""
        check_window_fits(x, self.extent, name=f"guard={self.guard} + train={self.train}")

    def offsets(self) -> Tensor:
        """``(N, 2)`` long tensor of the ring's (row, col) offsets, row-major order."""
        r = torch.arange(-self.outer, self.outer + 1)
        dr, dc = torch.meshgrid(r, r, indexing="ij")
        keep = (dr.abs() > self.guard) | (dc.abs() > self.guard)
        return torch.stack([dr[keep], dc[keep]], dim=-1)


@dataclass(frozen=True)
class Sums:
    """Local sums over a window: ``count`` valid cells, ``s1 = sum(x - shift)``,
    ``s2 = sum((x - shift)^2)`` (float64, ``(B, C, H, W)``; ``s2`` may be ``None``).

    ``shift`` is the per-image offset ``(B, C, 1, 1)`` subtracted before summing.
    """

    count: Tensor
    s1: Tensor
    s2: Tensor | None
    shift: Tensor

    def __sub__(self, other: Sums) -> Sums:
        s2 = None if self.s2 is None or other.s2 is None else self.s2 - other.s2
        return Sums(self.count - other.count, self.s1 - other.s1, s2, self.shift)

    def mean(self) -> Tensor:
        """Mean over the valid cells (0 where there are none), float64."""
        c = self.count.clamp_min(1)
        return torch.where(self.count > 0, self.s1 / c + self.shift, torch.zeros_like(self.s1))

    def var(self, *, unbiased: bool = False) -> Tensor:
        """Variance over the valid cells (population by default), float64, clamped >= 0."""
        if self.s2 is None:
            raise ValueError("this Sums was computed without second moments (moments=1)")
        c = self.count
        dof = (c - 1) if unbiased else c
        m = self.s1 / c.clamp_min(1)
        v = (self.s2 - m * self.s1) / dof.clamp_min(1)
        return torch.where(dof > 0, v.clamp_min(0), torch.zeros_like(v))


def _integral(xd: Tensor, pad: int) -> Tensor:
    """Zero-padded 2-D integral image (in place on ``xd``, which must already be padded by
    ``pad + 1`` zeros at the top/left and ``pad`` at the bottom/right):
    ``out[..., i, j] = sum(xd[..., :i, :j])``. Shape ``(..., H+2p+1, W+2p+1)``."""
    return xd.cumsum_(-1).cumsum_(-2)


def _padded(x: Tensor, shift: Tensor, pad: int, vmask: Tensor | None) -> Tensor:
    """``x - shift`` (zero where invalid) written into a zero float64 buffer with the
    padding :func:`_integral` expects; conversion, centring and padding in one pass."""
    b, c, h, w = x.shape
    buf = x.new_zeros((b, c, h + 2 * pad + 1, w + 2 * pad + 1), dtype=torch.float64)
    inner = buf[..., pad + 1 : pad + 1 + h, pad + 1 : pad + 1 + w]
    inner.copy_(x).sub_(shift)
    if vmask is not None:
        inner.masked_fill_(~vmask, 0.0)
    return buf


def _corner_sum(s: Tensor, rect: Rect, pad: int, h: int, w: int) -> Tensor:
    """Rectangle sums for every pixel from a padded integral image ``s`` (4 shifted slices)."""
    top, bot = pad + rect.r0, pad + rect.r1 + 1
    left, right = pad + rect.c0, pad + rect.c1 + 1
    out = s[..., bot : bot + h, right : right + w].clone()
    out.sub_(s[..., top : top + h, right : right + w])
    out.sub_(s[..., bot : bot + h, left : left + w])
    return out.add_(s[..., top : top + h, left : left + w])


def _axis_counts(n: int, lo: int, hi: int, device: torch.device) -> Tensor:
    """Number of in-range indices in ``[i + lo, i + hi]`` for ``i = 0..n-1``."""
    i = torch.arange(n, device=device, dtype=torch.float64)
    return ((i + hi).clamp(max=n - 1) - (i + lo).clamp(min=0) + 1).clamp_min(0)


def _pad_for(rects: tuple[Rect, ...]) -> int:
    return max(max(abs(r.r0), abs(r.r1), abs(r.c0), abs(r.c1)) for r in rects)


def rect_sums(
    x: Tensor,
    rects: tuple[Rect, ...] | list[Rect],
    *,
    valid: Tensor | None = None,
    moments: int = 2,
) -> list[Sums]:
    """Sums of ``x`` (and ``x^2``) over each rectangle, for every pixel.

    Args:
        x: real tensor ``(B, C, H, W)``.
        rects: rectangles of offsets relative to each pixel (see :class:`Rect`).
        valid: optional bool mask broadcastable to ``x``; invalid cells are not counted.
        moments: 1 for sums only, 2 to also return sums of squares.

    Returns:
        One :class:`Sums` per rectangle, float64 ``(B, C, H, W)``, sharing one integral image.

    Example:
        >>> x = torch.arange(16.0).reshape(1, 1, 4, 4)
        >>> rect_sums(x, [Rect.box(1)])[0].mean()[0, 0, 1, 1].item()
        5.0
    """
    rects = tuple(rects)
    b, c, h, w = x.shape
    vmask = None if valid is None else valid.expand_as(x)
    shift = _image_mean(x, vmask)
    pad = _pad_for(rects)
    xd = _padded(x, shift, pad, vmask)
    s2_int = _integral(xd * xd, pad) if moments >= 2 else None
    s1_int = _integral(xd, pad)
    cnt_int = None
    if vmask is not None:
        cnt_int = _integral(_padded(vmask, vmask.new_zeros(()), pad, None), pad)
    out = []
    for rect in rects:
        if cnt_int is None:
            rows = _axis_counts(h, rect.r0, rect.r1, x.device)
            cols = _axis_counts(w, rect.c0, rect.c1, x.device)
            count = (rows[:, None] * cols[None, :]).expand(b, c, h, w)
        else:
            count = _corner_sum(cnt_int, rect, pad, h, w).round_()
        s1 = _corner_sum(s1_int, rect, pad, h, w)
        s2 = None if s2_int is None else _corner_sum(s2_int, rect, pad, h, w)
        out.append(Sums(count, s1, s2, shift))
    return out


def _image_mean(x: Tensor, vmask: Tensor | None) -> Tensor:
    """Per-image, per-channel mean ``(B, C, 1, 1)`` float64 over valid cells (the summing
    offset; any offset is exact, the mean just keeps the integral image small)."""
    if x.numel() == 0:
        return x.new_zeros(x.shape[:2] + (1, 1), dtype=torch.float64)
    if vmask is None:
        return x.mean(dim=(-2, -1), keepdim=True, dtype=torch.float64)
    m = vmask.to(torch.float64)
    num = (x.to(torch.float64) * m).sum(dim=(-2, -1), keepdim=True)
    return num / m.sum(dim=(-2, -1), keepdim=True).clamp_min(1)


def box_sums(x: Tensor, radius: int, *, valid: Tensor | None = None, moments: int = 2) -> Sums:
    """Sums over the centred ``(2 radius + 1)^2`` box (the speckle filters' window)."""
    return rect_sums(x, [Rect.box(radius)], valid=valid, moments=moments)[0]


def ring_sums(
    x: Tensor, guard: int, train: int, *, valid: Tensor | None = None, moments: int = 2
) -> Sums:
    """Sums over the CFAR training ring (outer box minus guard box, CUT excluded).

    Example:
        >>> x = torch.ones(1, 1, 9, 9)
        >>> ring_sums(x, 1, 2).count[0, 0, 4, 4].item()  # 5x5 ring around a 3x3 guard box
        16.0
    """
    outer, inner = rect_sums(
        x, [Rect.box(guard + train), Rect.box(guard)], valid=valid, moments=moments
    )
    return outer - inner


def pinwheel_rects(guard: int, train: int) -> tuple[Rect, Rect, Rect, Rect]:
    """The 4 pinwheel blocks (top, right, bottom, left), each ``t x (2g+t+1)`` cells,
    tiling the ring exactly without overlap."""
    g, t = guard, train
    o = g + t
    return (
        Rect(-o, -g - 1, -o, g),  # top: t rows, columns from the left edge to +g
        Rect(-o, g, g + 1, o),  # right: t columns, rows from the top edge to +g
        Rect(g + 1, o, -g, o),  # bottom: t rows, columns from -g to the right edge
        Rect(-g, o, -o, -g - 1),  # left: t columns, rows from -g to the bottom edge
    )
