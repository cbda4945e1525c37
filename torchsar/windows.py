"""Window geometry and fast box / ring / block sums (our ``filter2d``).

Every window statistic in torchsar without a kernel of its own goes through
:func:`windowed` (:func:`rect_sums` for whole images): sums of ``x`` (and optionally
``x**2``) over rectangles placed at fixed offsets from each pixel, strip of rows by strip
of rows. On the CPU most detectors sum their windows in one-sweep kernels instead (CA, AC,
two-parameter, GO, SO, OS and the distribution CFARs, with and without no-data; VI and the
speckle filters without; :mod:`torchsar._box_kernels`); :func:`windowed` serves the rest
(VI with no-data, Gamma-MAP) and every window statistic on a GPU.

How the cells are summed:

- rectangles and rings (every shape the detectors use), on a GPU and, up to
  :data:`DIRECT_CELLS` cells (the default ring's 144, boxes up to 17 x 17), on the CPU
  with the compiled kernels: every cell added on its own in float64, as its deviation
  from a cell of the pixel's own window (the first in-image, valid one), in a fixed
  order. No integral image, so nothing cancels: a bright target elsewhere in the image
  leaves no residue in a window of clutter, a window of equal cells has sums of exactly
  0, and the CPU's sums are the GPU's bit for bit. The cost grows with the window's cells
  (the 144-cell ring: about 2.4x the integral images on one CPU thread).
- other regions, larger windows on the CPU, and without the compiled kernels: zero-padded
  float64 integral images of ``x - mean`` (the image's mean) read with four shifted slices
  per rectangle, at a cost per pixel independent of the window size.

Borders and no-data: cells outside the image never count, and an optional boolean ``valid``
mask removes no-data cells too. Every sum comes with the matching **count** of valid cells,
so a statistic near the border is the textbook statistic over the cells that exist. Interior
pixels (window fully inside, all valid) equal the textbook definition exactly.

Geometry: ``guard`` g is the half-width of the guard box (``(2g+1)^2`` cells,
CUT included, excluded from training); ``train`` t is the width of the training band; the
outer box is ``(2(g+t)+1)^2`` and the ring holds ``N = (2(g+t)+1)^2 - (2g+1)^2`` cells. The
pinwheel split cuts the ring into 4 equal blocks of ``t x (2g+t+1)`` cells: top, right,
bottom, left.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from torchsar import _jit, _triton
from torchsar._checks import check_int, check_window_fits

__all__ = [
    "DIRECT_CELLS",
    "Rect",
    "Region",
    "Ring",
    "Sums",
    "box_sums",
    "disjoint_rects",
    "distance_shells",
    "exp_distance_mean",
    "pinwheel_rects",
    "rect_sums",
    "region_count",
    "ring_counts",
    "ring_sums",
    "strip_rows",
    "windowed",
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
class Region:
    """A signed sum of rectangles, e.g. a CFAR ring = outer box minus guard box.

    Summing over a region costs four slices per rectangle, independent of its area.
    """

    plus: tuple[Rect, ...]
    minus: tuple[Rect, ...] = ()

    @property
    def area(self) -> int:
        """Number of cells (rectangles in ``minus`` must lie inside those in ``plus``)."""
        return sum(r.area for r in self.plus) - sum(r.area for r in self.minus)

    def signed(self) -> list[tuple[int, Rect]]:
        """``[(+1, rect), ..., (-1, rect), ...]``."""
        return [(1, r) for r in self.plus] + [(-1, r) for r in self.minus]


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

    @property
    def region(self) -> Region:
        """The training ring as a :class:`Region` (outer box minus guard box)."""
        return Region((Rect.box(self.outer),), (Rect.box(self.guard),))

    def check_fits(self, x: Tensor) -> None:
        """Raise :class:`~torchsar.errors.WindowSizeError` if the ring exceeds ``x``."""
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

    ``shift`` is the offset subtracted before summing: per pixel ``(B, C, H, W)`` (a cell
    of the pixel's own window, where the cells are added directly), or per image ``(B, C,
    1, 1)`` (the image's mean, for integral images); the same for every region of one call,
    so sums of disjoint regions add.
    """

    count: Tensor
    s1: Tensor
    s2: Tensor | None
    shift: Tensor

    def __sub__(self, other: Sums) -> Sums:
        s2 = None if self.s2 is None or other.s2 is None else self.s2 - other.s2
        return Sums(self.count - other.count, self.s1 - other.s1, s2, self.shift)

    def shifts(self) -> Tensor:
        """``shift`` as a plane of ``s1``'s shape (a per-image shift broadcast, not copied)."""
        return self.shift.expand_as(self.s1)

    def mean(self) -> Tensor:
        """Mean over the valid cells (0 where there are none), float64."""
        c = self.count.clamp_min(1)
        return torch.where(self.count > 0, self.s1 / c + self.shift, torch.zeros_like(self.s1))

    def mean_(self) -> Tensor:
        """:meth:`mean` computed in place in ``s1`` (which must not be needed afterwards)."""
        m = self.s1.div_(self.count.clamp_min(1)).add_(self.shift)
        empty = self.count <= 0
        return m.masked_fill_(empty, 0.0) if bool(empty.any()) else m

    def var(self, *, unbiased: bool = False) -> Tensor:
        """Variance over the valid cells (population by default), float64, clamped >= 0."""
        if self.s2 is None:
            raise ValueError("this Sums was computed without second moments (moments=1)")
        c = self.count
        dof = (c - 1) if unbiased else c
        m = self.s1 / c.clamp_min(1)
        v = (self.s2 - m * self.s1) / dof.clamp_min(1)
        return torch.where(dof > 0, v.clamp_min(0), torch.zeros_like(v))


def _integral(buf: Tensor) -> Tensor:
    """In-place 2-D integral image of a buffer whose first row and column are zero:
    afterwards ``buf[..., i, j] = sum(original[..., :i, :j])``."""
    return buf.cumsum_(-1).cumsum_(-2)


def _corner_sum(s: Tensor, region: Region, pad: int, h: int, w: int) -> Tensor:
    """Region sums for ``h x w`` pixels from a padded integral image: four shifted slices
    per signed rectangle, accumulated in place."""
    out: Tensor | None = None
    for sign, rect in region.signed():
        top, bot = pad + rect.r0, pad + rect.r1 + 1
        left, right = pad + rect.c0, pad + rect.c1 + 1
        corners = (
            (sign, s[..., bot : bot + h, right : right + w]),
            (-sign, s[..., top : top + h, right : right + w]),
            (-sign, s[..., bot : bot + h, left : left + w]),
            (sign, s[..., top : top + h, left : left + w]),
        )
        for sg, view in corners:
            if out is None:
                out = view.clone() if sg > 0 else -view
            elif sg > 0:
                out.add_(view)
            else:
                out.sub_(view)
    assert out is not None  # a Region has at least one rectangle
    return out


def _region_count(region: Region, n_rows: int, n_cols: int, r: int, rr: int, device) -> Tensor:
    """In-image cell counts of a region for rows ``[r, r + rr)``: ``(rr, W)`` float64 (a
    fresh copy of counts remembered per geometry: every batch of one image size has them)."""
    return _region_count_cached(region, n_rows, n_cols, r, rr, device).clone()


@functools.lru_cache(maxsize=64)
def _region_count_cached(
    region: Region, n_rows: int, n_cols: int, r: int, rr: int, device
) -> Tensor:
    out = torch.zeros((rr, n_cols), dtype=torch.float64, device=device)
    for sign, rect in region.signed():
        rows = _axis_counts(n_rows, rect.r0, rect.r1, r, r + rr, device)
        cols = _axis_counts(n_cols, rect.c0, rect.c1, 0, n_cols, device)
        out += sign * rows[:, None] * cols[None, :]
    return out


def region_count(
    h: int, w: int, shape: Rect | Region, device: torch.device | None = None
) -> Tensor:
    """In-image cell count of a rectangle or region at every pixel of an ``h x w`` image,
    float64 ``(h, w)`` (no mask: the counts only depend on the geometry).

    Examples:
        >>> n = region_count(9, 9, Ring(1, 2).region)
        >>> n[4, 4].item(), n[0, 0].item()  # full ring; corner: 4x4 box minus 2x2 guard
        (40.0, 12.0)
    """
    return _region_count(_as_region(shape), h, w, 0, h, device)


@functools.lru_cache(maxsize=64)
def ring_counts(h: int, w: int, ring: Ring) -> frozenset[int]:
    """Every count of in-image ring cells that occurs in an ``h x w`` image (the interior's
    ``N`` and the frame's smaller ones), from the per-axis counts of the outer and guard
    boxes.

    Examples:
        >>> sorted(ring_counts(9, 9, Ring(1, 2)))[-3:]
        [27, 33, 40]
    """

    def axis(n: int) -> set[tuple[int, int]]:
        i = np.arange(n)
        outer = np.minimum(i + ring.outer, n - 1) - np.maximum(i - ring.outer, 0) + 1
        guard = np.minimum(i + ring.guard, n - 1) - np.maximum(i - ring.guard, 0) + 1
        return set(zip(outer.tolist(), guard.tolist(), strict=True))

    return frozenset(ro * co - rg * cg for ro, rg in axis(h) for co, cg in axis(w))


def _as_region(shape: Rect | Region) -> Region:
    return shape if isinstance(shape, Region) else Region((shape,))


def _axis_counts(n: int, lo: int, hi: int, start: int, stop: int, device: torch.device) -> Tensor:
    """Number of in-range indices in ``[i + lo, i + hi]`` for ``i = start..stop-1``, ``0..n-1``."""
    i = torch.arange(start, stop, device=device, dtype=torch.float64)
    return ((i + hi).clamp(max=n - 1) - (i + lo).clamp(min=0) + 1).clamp_min(0)


def _pad_for(regions: tuple[Region, ...]) -> int:
    rects = [r for reg in regions for _, r in reg.signed()]
    return max(max(abs(r.r0), abs(r.r1), abs(r.c0), abs(r.c1)) for r in rects)


def _image_mean(x: Tensor, vmask: Tensor | None) -> Tensor:
    """Per-image, per-channel mean ``(B, C, 1, 1)`` float64 over valid cells (the summing
    offset; any offset is exact, the mean just keeps the integral image small)."""
    if x.numel() == 0:
        return x.new_zeros((*x.shape[:2], 1, 1), dtype=torch.float64)
    if vmask is None:
        return x.mean(dim=(-2, -1), keepdim=True, dtype=torch.float64)
    m = vmask.to(torch.float64)
    num = (x.to(torch.float64) * m).sum(dim=(-2, -1), keepdim=True)
    return num / m.sum(dim=(-2, -1), keepdim=True).clamp_min(1)


def _strip_buffer(src: Tensor, r: int, rr: int, pad: int, shift: Tensor | None) -> Tensor:
    """Float64 zero buffer ``(B, C, rr + 2 pad + 1, W + 2 pad + 1)`` holding rows
    ``[r - pad, r + rr + pad)`` of ``src - shift`` (zeros outside the image), first row and
    column left zero for the integral image."""
    b, c, h, w = src.shape
    buf = torch.zeros(
        (b, c, rr + 2 * pad + 1, w + 2 * pad + 1), dtype=torch.float64, device=src.device
    )
    lo, hi = max(r - pad, 0), min(r + rr + pad, h)
    dst = buf[..., 1 + lo - (r - pad) : 1 + hi - (r - pad), pad + 1 : pad + 1 + w]
    dst.copy_(src[..., lo:hi, :])
    if shift is not None:
        dst.sub_(shift)
    return buf


def _strip_sums(
    x: Tensor,
    rects: tuple[Region, ...],
    r: int,
    rr: int,
    pad: int,
    shift: Tensor | None,
    vmask: Tensor | None,
    moments: int,
) -> list[Sums]:
    """:class:`Sums` of every region for output rows ``[r, r + rr)``: every cell added
    directly where ``shift`` is ``None`` (:func:`_direct`), else of ``x - shift`` by
    integral images."""
    h, w = x.shape[-2:]
    if shift is None:
        return _direct_strip_sums(x, rects, r, rr, vmask, moments)
    if _jit.for_tensor(x):
        return _compiled_strip_sums(x, rects, r, rr, pad, shift, vmask, moments)
    buf = _strip_buffer(x, r, rr, pad, shift)
    cnt = None
    if vmask is not None:
        vbuf = _strip_buffer(vmask, r, rr, pad, None)
        buf.mul_(vbuf)
        cnt = _integral(vbuf)
    s2 = _integral(buf * buf) if moments >= 2 else None
    s1 = _integral(buf.clone() if buf.requires_grad else buf)  # autograd saved buf (buf * buf)
    out = []
    for rect in rects:
        if cnt is None:
            count = _region_count(rect, h, w, r, rr, x.device)
        else:
            count = _corner_sum(cnt, rect, pad, rr, w).round_()
        out.append(
            Sums(
                count,
                _corner_sum(s1, rect, pad, rr, w),
                None if s2 is None else _corner_sum(s2, rect, pad, rr, w),
                shift,
            )
        )
    return out


def _compiled_strip_sums(
    x: Tensor,
    rects: tuple[Region, ...],
    r: int,
    rr: int,
    pad: int,
    shift: Tensor,
    vmask: Tensor | None,
    moments: int,
) -> list[Sums]:
    """:func:`_strip_sums` by :func:`torchsar._windows_kernels.strip_sums`."""
    from torchsar import _windows_kernels

    b, c, h, w = x.shape
    table = np.array(
        [
            (q, sign, pad + t.r0, pad + t.r1 + 1, pad + t.c0, pad + t.c1 + 1)
            for q, reg in enumerate(rects)
            for sign, t in reg.signed()
        ],
        dtype=np.int64,
    )
    mask = np.zeros((1, 1, 1, 1), np.bool_) if vmask is None else vmask.contiguous().numpy()
    cnt, s1, s2 = _windows_kernels.strip_sums(
        x.detach().contiguous().numpy(),
        r,
        rr,
        pad,
        shift.reshape(b, c).numpy(),
        mask,
        vmask is not None,
        moments,
        table,
        len(rects),
    )
    cnt, s1, s2 = torch.from_numpy(cnt), torch.from_numpy(s1), torch.from_numpy(s2)
    out = []
    for q, rect in enumerate(rects):
        count = _region_count(rect, h, w, r, rr, x.device) if vmask is None else cnt[q]
        out.append(Sums(count, s1[q], s2[q] if moments >= 2 else None, shift))
    return out


def disjoint_rects(region: Region) -> list[tuple[int, int, int, int]] | None:
    """The region as disjoint rectangles ``(r0, r1, c0, c1)`` to add cell by cell: a single
    rectangle as it is, one rectangle minus one inside it (a ring) as the up to four bands
    around the hole (above, below, left, right); ``None`` for other regions.

    Examples:
        >>> disjoint_rects(Ring(1, 2).region)
        [(-3, -2, -3, 3), (2, 3, -3, 3), (-1, 1, -3, -2), (-1, 1, 2, 3)]
    """
    if len(region.plus) != 1 or len(region.minus) > 1:
        return None
    (p,) = region.plus
    if not region.minus:
        return [(p.r0, p.r1, p.c0, p.c1)]
    (m,) = region.minus
    if not (p.r0 <= m.r0 <= m.r1 <= p.r1 and p.c0 <= m.c0 <= m.c1 <= p.c1):
        return None
    bands = [
        (p.r0, m.r0 - 1, p.c0, p.c1),
        (m.r1 + 1, p.r1, p.c0, p.c1),
        (m.r0, m.r1, p.c0, m.c0 - 1),
        (m.r0, m.r1, m.c1 + 1, p.c1),
    ]
    return [b for b in bands if b[0] <= b[1] and b[2] <= b[3]]


DIRECT_CELLS = 320
"""On the CPU, the most window cells (over all regions of one call) summed cell by cell;
more take the integral images, whose cost does not grow with the window (cell by cell
costs about 0.08 ms per cell and moment pair on a 512 x 512 image on one thread: the
default ring's 144 cells 2.4x the integral images)."""


def _direct(x: Tensor, regions: tuple[Region, ...]) -> bool:
    """Whether the window sums of ``x`` add every cell directly (the Triton kernel on a GPU,
    whatever the window; :func:`torchsar._windows_kernels.direct_sums` on the CPU, the same
    additions in the same order, up to :data:`DIRECT_CELLS` cells): every region a
    rectangle or a ring. Then they need no image mean, their shifts being per pixel."""
    if not all(disjoint_rects(reg) is not None for reg in regions):
        return False
    if _triton.for_tensor(x):
        return True
    return _jit.for_tensor(x) and sum(reg.area for reg in regions) <= DIRECT_CELLS


def _direct_strip_sums(
    x: Tensor, rects: tuple[Region, ...], r: int, rr: int, vmask: Tensor | None, moments: int
) -> list[Sums]:
    """:func:`_strip_sums` with every window cell added directly in float64, as deviations
    from a cell of the pixel's own window (the sums' ``shift`` is a plane ``(B, C, rr, W)``,
    not the image's mean; with no-data, the valid cells summed and counted): by the Triton
    kernel (:func:`torchsar._gpu_kernels.region_sums`) where it takes ``x``, else by
    :func:`torchsar._windows_kernels.direct_sums` (the same values bit for bit); every
    region a rectangle or a ring (:func:`_direct`)."""
    parts = [disjoint_rects(reg) for reg in rects]
    h, w = x.shape[-2:]
    if _triton.for_tensor(x):
        s1, s2, shift, cnt = _triton.kernels().region_sums(x, parts, r, rr, moments, vmask)
    else:
        s1, s2, shift, cnt = _cpu_direct_sums(x, parts, r, rr, moments, vmask)
    return [
        Sums(
            _region_count(reg, h, w, r, rr, x.device) if cnt is None else cnt[q],
            s1[q],
            None if s2 is None else s2[q],
            shift,
        )
        for q, reg in enumerate(rects)
    ]


def _cpu_direct_sums(
    x: Tensor,
    parts: list[list[tuple[int, int, int, int]]],
    r: int,
    rr: int,
    moments: int,
    vmask: Tensor | None,
) -> tuple[Tensor, Tensor | None, Tensor, Tensor | None]:
    """:func:`torchsar._gpu_kernels.region_sums`' results by the numba kernel."""
    from torchsar import _windows_kernels

    b, c, h, w = x.shape
    planes = x.detach().reshape(-1, h, w).contiguous().numpy()
    if vmask is None:
        flags = np.zeros((1, 1, 1), np.uint8)
    else:
        flags = vmask.expand_as(x).reshape(-1, h, w).to(torch.uint8).contiguous().numpy()
    rects = np.array([rect for region in parts for rect in region], np.int64).reshape(-1, 4)
    starts = np.cumsum([0] + [len(region) for region in parts]).astype(np.int64)
    s1, s2, shift, cnt = _windows_kernels.direct_sums(
        planes, flags, vmask is not None, rects, starts, r, rr, moments
    )
    k = len(parts)

    def shaped(a: np.ndarray) -> Tensor:
        return torch.from_numpy(a).reshape(k, b, c, rr, w)

    return (
        shaped(s1),
        shaped(s2) if moments >= 2 else None,
        torch.from_numpy(shift).reshape(b, c, rr, w),
        shaped(cnt) if vmask is not None else None,
    )


_STRIP_ELEMENTS = 1 << 17  # float64 strip rows of ~1 MB per image stay cache-resident


def strip_rows(x: Tensor, pad: int, strip: int | None = None) -> int:
    """Rows per strip of a window statistic over ``x`` with windows ``pad`` cells past the
    pixel (``strip``: a given height). Depends on the image width only, never on the batch
    size, so every image is summed in the same strips whatever batch it comes in
    (bit-identical results)."""
    h, w = x.shape[-2:]
    if strip is not None:
        return max(1, min(strip, h))
    return max(1, min(h, max(16, _STRIP_ELEMENTS // (w + 2 * pad + 1))))


_GPU_STRIP_ELEMENTS = 1 << 24  # float64 sums per region and moment per strip: 128 MB


def _gpu_strip_rows(x: Tensor) -> int:
    """Rows per strip where the Triton kernel sums the windows: as many as keep each float64
    sum plane of the strip within ``_GPU_STRIP_ELEMENTS`` (a whole 1024^2 image, a quarter
    of a batch of 64 of them): fewer launches. The kernel sums every pixel's window on its
    own, so the strips do not change a value."""
    b, c, h, w = x.shape
    return max(16, min(h, _GPU_STRIP_ELEMENTS // max(1, b * c * w)))


def windowed(
    x: Tensor,
    rects: Sequence[Rect | Region],
    fn: Callable[..., Tensor | tuple[Tensor, ...]],
    *,
    valid: Tensor | None = None,
    moments: int = 2,
    extras: tuple[Tensor, ...] = (),
    strip: int | None = None,
) -> Tensor | tuple[Tensor, ...]:
    """Compute a local statistic from rectangle sums, row strip by row strip.

    This is the one mechanism behind every window statistic: for each strip of output rows it
    sums every region around each pixel (cell by cell as deviations from a cell of the
    pixel's window where the regions are rectangles or rings and the compiled kernels or
    a GPU take ``x``, else from float64 integral images of ``x - mean``: see the module
    notes) and calls ``fn(x_strip, sums, *extra_strips)``. Memory stays bounded by the strip
    size.

    Args:
        x: real tensor ``(B, C, H, W)`` (validated by the caller).
        rects: rectangles (or signed :class:`Region` sums of rectangles, e.g. ``Ring.region``)
            of offsets relative to each pixel.
        fn: ``fn(x_strip, sums, *extra_strips) -> Tensor | tuple[Tensor, ...]``; ``x_strip`` is
            ``x[..., r:r+rr, :]``, ``sums`` a list of :class:`Sums` (one per rect, float64
            ``(B, C, rr, W)``; ``count`` may be a broadcastable ``(rr, W)`` when there is no
            ``valid`` mask), ``extra_strips`` the same rows of each tensor in ``extras``.
            It must return tensors of shape ``(B, C, rr, W)``.
        valid: optional bool mask broadcastable to ``x``; invalid cells are never counted.
        moments: 1 for sums only, 2 to also provide sums of squares.
        extras: tensors ``(B, C, H, W)`` sliced alongside ``x`` and passed to ``fn``.
        strip: rows per strip (default: sized so float64 buffers stay around 1 MB).

    Returns:
        What ``fn`` returns, assembled to full height ``(B, C, H, W)``.
    """
    regions = tuple(_as_region(r) for r in rects)
    h, w = x.shape[-2:]
    vmask = None if valid is None else valid.expand_as(x)
    shift = None if _direct(x, regions) else _image_mean(x, vmask)
    pad = _pad_for(regions)
    rows = strip_rows(x, pad, strip)
    if strip is None and _triton.for_tensor(x):
        rows = _gpu_strip_rows(x)
    outs: list[Tensor] = []
    single = False
    for r in range(0, max(h, 1), rows):
        rr = min(rows, h - r)
        sums = _strip_sums(x, regions, r, rr, pad, shift, vmask, moments)
        res = fn(x[..., r : r + rr, :], sums, *(e[..., r : r + rr, :] for e in extras))
        single = isinstance(res, Tensor)
        parts = (res,) if single else tuple(res)
        if not outs:
            outs = [p.new_empty((*p.shape[:-2], h, w)) for p in parts]
        for o, p in zip(outs, parts, strict=True):
            o[..., r : r + rr, :] = p
    return outs[0] if single else tuple(outs)


def rect_sums(
    x: Tensor,
    rects: Sequence[Rect | Region],
    *,
    valid: Tensor | None = None,
    moments: int = 2,
) -> list[Sums]:
    """Full-image :class:`Sums` over each rectangle or region (float64, ``(B, C, H, W)``).

    Convenient for small images and tests; statistics on large images should use
    :func:`windowed`, which never materialises full-size float64 sums.

    Examples:
        >>> x = torch.arange(16.0).reshape(1, 1, 4, 4)
        >>> rect_sums(x, [Rect.box(1)])[0].mean()[0, 0, 1, 1].item()
        5.0
    """
    rects = tuple(rects)
    per_pixel = _direct(x, tuple(_as_region(r) for r in rects))

    def collect(_xs: Tensor, sums: list[Sums]) -> tuple[Tensor, ...]:
        out: list[Tensor] = []
        for s in sums:
            out += [s.count.expand_as(s.s1), s.s1, s.s1 if s.s2 is None else s.s2]
        return (*out, sums[0].shift.expand_as(sums[0].s1)) if per_pixel else tuple(out)

    flat = windowed(x, rects, collect, valid=valid, moments=moments)
    vmask = None if valid is None else valid.expand_as(x)
    shift = flat[-1] if per_pixel else _image_mean(x, vmask)
    return [
        Sums(flat[3 * i], flat[3 * i + 1], flat[3 * i + 2] if moments >= 2 else None, shift)
        for i in range(len(rects))
    ]


def box_sums(x: Tensor, radius: int, *, valid: Tensor | None = None, moments: int = 2) -> Sums:
    """Sums over the centred ``(2 radius + 1)^2`` box (the speckle filters' window)."""
    return rect_sums(x, [Rect.box(radius)], valid=valid, moments=moments)[0]


def ring_sums(
    x: Tensor, guard: int, train: int, *, valid: Tensor | None = None, moments: int = 2
) -> Sums:
    """Sums over the CFAR training ring (outer box minus guard box, CUT excluded).

    Examples:
        >>> x = torch.ones(1, 1, 9, 9)
        >>> ring_sums(x, 1, 2).count[0, 0, 4, 4].item()  # 7x7 box minus the 3x3 guard box
        40.0
    """
    return rect_sums(x, [Ring(guard, train).region], valid=valid, moments=moments)[0]


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


# --- isotropic distance weights (Frost-type filters) -------------------------------------------


def distance_shells(radius: int) -> list[tuple[int, tuple[tuple[int, int], ...]]]:
    """Offsets of the ``(2 radius + 1)^2`` box grouped by Euclidean distance to the centre.

    Each shell is ``(d2, orbits)``: the squared distance ``d2`` and the offset orbits
    ``(p, q)``, ``0 <= p <= q <= radius``, with ``p^2 + q^2 = d2``. An orbit stands for every
    offset ``(±p, ±q)`` and ``(±q, ±p)``; shells are sorted by distance.

    Examples:
        >>> [d2 for d2, _ in distance_shells(1)]
        [0, 1, 2]
    """
    check_int(radius, "radius", minimum=0)
    shells: dict[int, list[tuple[int, int]]] = {}
    for p in range(radius + 1):
        for q in range(p, radius + 1):
            shells.setdefault(p * p + q * q, []).append((p, q))
    return [(d2, tuple(orbits)) for d2, orbits in sorted(shells.items())]


def _pair_counts(n: int, start: int, stop: int, radius: int, device, dtype) -> Tensor:
    """``(radius + 1, stop - start)``: how many of ``i - p`` and ``i + p`` (just ``i`` for
    ``p = 0``) lie in ``[0, n)``, for ``p = 0..radius`` and ``i = start..stop-1``."""
    i = torch.arange(start, stop, device=device)
    p = torch.arange(radius + 1, device=device)[:, None]
    both = ((i - p) >= 0).to(dtype) + ((i + p) < n).to(dtype)
    return torch.where(p == 0, torch.ones_like(both), both)


def _orbit_sums(v: list[Tensor], p: int, q: int, radius: int, w: int) -> Tensor:
    """Sum of the padded strip over the orbit ``(±p, ±q), (±q, ±p)``; ``v[p]`` holds the
    vertical pair sums ``x[i - p] + x[i + p]`` (``x`` for ``p = 0``), ``radius`` columns of
    zero padding on each side."""

    def horizontal(a: Tensor, b: int) -> Tensor:
        if b == 0:
            return a[..., radius : radius + w]
        return a[..., radius - b : radius - b + w] + a[..., radius + b : radius + b + w]

    s = horizontal(v[p], q)
    return s if p == q else s.add_(horizontal(v[q], p))


def _exp_distance_strip(
    x: Tensor, decay: Tensor, r: int, rr: int, radius: int, shells: list
) -> Tensor:
    """:func:`exp_distance_mean` for output rows ``[r, r + rr)`` (``decay`` already sliced)."""
    h, w = x.shape[-2:]
    buf = x.new_zeros((*x.shape[:-2], rr + 2 * radius, w + 2 * radius))
    lo, hi = max(r - radius, 0), min(r + rr + radius, h)
    buf[..., lo - (r - radius) : hi - (r - radius), radius : radius + w] = x[..., lo:hi, :]
    mid = buf[..., radius : radius + rr, :]
    v = [mid] + [
        buf[..., radius - p : radius - p + rr, :] + buf[..., radius + p : radius + p + rr, :]
        for p in range(1, radius + 1)
    ]
    rows = _pair_counts(h, r, r + rr, radius, x.device, x.dtype)
    if r >= radius and r + rr + radius <= h:
        rows = rows[:, :1]  # interior strip: the same counts on every row, broadcast them
    cols = _pair_counts(w, 0, w, radius, x.device, x.dtype)
    num = mid[..., radius : radius + w].clone()  # the centre cell, weight exp(0) = 1
    den = torch.ones_like(num)
    for d2, orbits in shells[1:]:
        s = _orbit_sums(v, *orbits[0], radius, w)
        for p, q in orbits[1:]:
            s.add_(_orbit_sums(v, p, q, radius, w))
        n = sum(
            rows[p, :, None] * cols[q] + (rows[q, :, None] * cols[p] if p != q else 0)
            for p, q in orbits
        )
        e = torch.mul(decay, -(d2**0.5)).exp_()
        num.addcmul_(e, s)
        den.addcmul_(e, n)
    return num.div_(den)


def exp_distance_mean(x: Tensor, radius: int, decay: Tensor, *, strip: int | None = None) -> Tensor:
    """Local mean weighted by ``exp(-decay * d)``, with a per-pixel ``decay`` (Frost kernel).

    ``out[i, j] = sum_k exp(-decay[i, j] d_k) x[k] / sum_k exp(-decay[i, j] d_k)`` over the
    cells ``k`` of the ``(2 radius + 1)^2`` box around ``(i, j)`` that lie inside the image,
    ``d_k`` the Euclidean distance (pixels) from ``k`` to ``(i, j)``. Exact weights, no
    per-pixel kernels: cells are grouped into distance shells (:func:`distance_shells`), the
    shell sums ``S_d`` come from shifted slices of a zero-padded row strip (vertical pair sums,
    then horizontal pairs: ``(radius + 1)^2`` additions per pixel) and the result is
    ``sum_d exp(-decay d) S_d / sum_d exp(-decay d) n_d``, with ``n_d`` the in-image cell
    count of the shell (the constant shell size at interior pixels). Memory is linear in
    the image; one ``exp`` per shell and pixel.

    Args:
        x: real tensor ``(B, C, H, W)`` (validated by the caller); the result has its dtype.
        radius: half-width of the box.
        decay: non-negative, broadcastable to ``x`` (e.g. ``damping * Ci^2``); ``inf`` keeps
            only the centre cell.
        strip: rows per strip (default: sized so strip buffers stay around 1 MB).

    Returns:
        ``(B, C, H, W)`` weighted means (``decay = 0`` gives the in-image box mean).

    Examples:
        >>> x = torch.arange(9.0).reshape(1, 1, 3, 3)
        >>> exp_distance_mean(x, 1, torch.zeros(1, 1, 3, 3))[0, 0, 1, 1].item()
        4.0
    """
    h = x.shape[-2]
    decay = decay.to(x.dtype).expand_as(x)
    shells = distance_shells(radius)
    rows = strip_rows(x, radius, strip)
    out = torch.empty_like(x)
    for r in range(0, h, rows):
        rr = min(rows, h - r)
        d = decay[..., r : r + rr, :]
        out[..., r : r + rr, :] = _exp_distance_strip(x, d, r, rr, radius, shells)
    return out
