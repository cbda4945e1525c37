"""Shared CFAR machinery: input handling, the border rule, and the statistic assembly.

Border rule (applies to every ring-based variant): ring cells outside the image or marked
invalid by ``valid`` are not counted. A pixel with fewer training cells than the interior
``N`` keeps its own exact threshold by rescaling its statistic by
``factor(N) / factor(n_pixel)``, so one global threshold (the interior factor) is exact at
every pixel and ROC sweeps stay consistent. Interior pixels are untouched. Pixels whose cell
under test is invalid, or whose ring has no valid cell, get statistic ``-inf``.

Every detector begins with :func:`prepare` and ends with :func:`conclude`: the ring
statistic is cast and its untestable pixels marked by :func:`finish` (inside the strip
callback of :func:`~torchsar.windows.windowed`), and :func:`conclude` marks the invalid
cells under test and builds the :class:`~torchsar.detection.Detection`.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable

import numpy as np
import torch
from torch import Tensor

from torchsar._checks import check_image, check_mask, check_probability, float_dtype
from torchsar._scale import power_of_two
from torchsar.cfar.thresholds import factor_map
from torchsar.detection import Detection, detection_from
from torchsar.errors import InputValueError
from torchsar.windows import Ring, ring_counts

__all__ = [
    "border_scale",
    "conclude",
    "finish",
    "geometric_scale",
    "kernel_planes",
    "one_sweep",
    "out_dtype",
    "prepare",
    "ratio",
    "ratio_",
    "rescale_border_",
    "rescale_frame_",
    "square_safe_planes",
]


def prepare(
    x: Tensor,
    guard: int,
    train: int,
    pfa: float,
    valid: Tensor | None,
    *,
    detector: str,
    values: bool = True,
) -> tuple[Ring, float, Tensor | None]:
    """Validate the common CFAR arguments of ``detector`` (its name, for messages); return
    the ring, ``pfa`` and the bool mask. ``values=False`` leaves the image's values to the
    caller (a kernel that checks them as it reads them, after the detector's own options)."""
    check_image(x, "x", not_differentiable=detector, values=values)
    ring = Ring(guard, train)
    ring.check_fits(x)
    pfa = check_probability(pfa, "pfa")
    vmask = None if valid is None else check_mask(valid, x, "valid")
    return ring, pfa, vmask


def kernel_planes(x: Tensor) -> Tensor:
    """The ``(P, H, W)`` planes of ``x`` as a compiled kernel reads them: detached, a lazily
    negated view resolved, contiguous."""
    return x.detach().resolve_neg().reshape(-1, *x.shape[-2:]).contiguous()


def one_sweep(
    x: Tensor,
    planes: Tensor,
    dtype: torch.dtype,
    threshold: float,
    kernel: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], int],
) -> Detection:
    """A one-sweep CPU kernel's detection: ``kernel(planes, threshold, out, mask)`` writes
    the statistic (``dtype``) and the mask ``statistic > threshold`` (the threshold an array
    of one value of ``dtype``) of the ``(P, H, W)`` ``planes`` of ``x``, and returns how many
    values it read that are not a finite number ``>= 0``: any, and the tensor code's check
    raises its error on the caller's tensor."""
    out = torch.empty(planes.shape, dtype=dtype)
    mask = torch.empty(planes.shape, dtype=torch.bool)
    thr = torch.as_tensor(threshold, dtype=dtype)
    if kernel(planes.numpy(), thr.reshape(1).numpy(), out.numpy(), mask.numpy()):
        refuse_values(x)
    return Detection(mask=mask.view(x.shape), statistic=out.view(x.shape), threshold=thr)


def refuse_values(x: Tensor) -> None:
    """Raise the input check's error for ``x``, in which a compiled kernel counted values
    that are not a finite number ``>= 0``."""
    check_image(x.detach(), "x")
    raise InputValueError("x must be finite and non-negative")  # not reached


def valid_planes(vmask: Tensor | None, x: Tensor) -> np.ndarray:
    """A no-data mask as the one-sweep kernels read it: uint8 ``(P, H, W)`` planes of
    ``x``'s shape (1 for a valid cell), or a ``(1, 1, 1)`` placeholder without a mask."""
    if vmask is None:
        return np.ones((1, 1, 1), np.uint8)
    planes = vmask.expand_as(x).reshape(-1, *x.shape[-2:])
    return planes.contiguous().view(torch.uint8).numpy()


def square_safe_planes(x: Tensor) -> tuple[Tensor, bool]:
    """The ``(P, H, W)`` planes of ``x`` for a compiled kernel that sums squares in float64:
    a float64 plane whose peak lies outside ``[2^-384, 2^384]`` is divided by the power of
    two that brings its peak into ``[1, 2)`` (exact; the statistics that sum squares are
    ratios, free of the scale), so its squares neither overflow nor underflow. Also whether
    any plane was divided (a tiny negative value could then read as ``-0.0``: the caller
    checks the values before)."""
    planes = kernel_planes(x)
    if x.dtype != torch.float64 or planes.numel() == 0:
        return planes, False
    peak = planes.abs().amax(dim=(-2, -1), keepdim=True)
    outside = (peak > 2.0**384) | ((peak > 0) & (peak < 2.0**-384))
    if not bool(outside.any()):
        return planes, False
    return planes / torch.where(outside, power_of_two(peak), 1.0), True


def stack_planes(planes: list[Tensor]) -> Tensor:
    """``K`` count or sum planes, ``(rr, W)`` or ``(B, C, rr, W)``, as one contiguous float64
    ``(K, B or 1, C or 1, rr, W)`` array for the kernels."""
    planes = [p if p.dim() == 4 else p.view(1, 1, *p.shape[-2:]) for p in planes]
    if len({tuple(p.shape) for p in planes}) > 1:
        planes = list(torch.broadcast_tensors(*planes))
    adjacent = _adjacent(planes)
    if adjacent is not None:
        return adjacent
    return torch.stack(planes).to(torch.float64).contiguous()


def _adjacent(planes: list[Tensor]) -> Tensor | None:
    """The planes as one ``(K, ...)`` view, without a copy, when they lie one after the other
    in memory as contiguous float64 tensors of one shape (the window sums of one strip do)."""
    first = planes[0]
    step = first.numel() * first.element_size()
    if not all(
        p.dtype == torch.float64
        and p.is_contiguous()
        and p.shape == first.shape
        and p.data_ptr() == first.data_ptr() + i * step
        for i, p in enumerate(planes)
    ):
        return None
    return torch.as_strided(first, (len(planes), *first.shape), (first.numel(), *first.stride()))


_GEOMETRIC: OrderedDict = OrderedDict()
_GEOMETRIC_SIZE = 16


def geometric_cached(
    key: tuple, counts: list[Tensor], make: Callable[[], Tensor | None], *, geometric: bool
):
    """``make()``, remembered for counts that depend only on the window geometry
    (``geometric``: no no-data mask; ``(rr, W)`` planes or planes with unit batch and
    channel dims, the same for every batch of images of one size): the border factors of the
    rules then cost one evaluation per strip of a image size, not one per batch. ``key``
    names everything else ``make`` depends on; the counts' values and device are part of the
    key (a value made on one device is never handed to another). Other counts, and counts
    of a no-data mask (whose bytes, hashed and kept as a key, would cost more time and
    memory than the factors: 8 MB per 512 x 512 image), get ``make()`` as is."""
    if not geometric or any(c.dim() > 2 and (c.shape[0] != 1 or c.shape[1] != 1) for c in counts):
        return make()
    full = (
        key,
        str(counts[0].device),
        *((tuple(c.shape), c.cpu().numpy().tobytes()) for c in counts),
    )
    if full in _GEOMETRIC:
        _GEOMETRIC.move_to_end(full)
        return _GEOMETRIC[full]
    value = make()
    _GEOMETRIC[full] = value
    if len(_GEOMETRIC) > _GEOMETRIC_SIZE:
        _GEOMETRIC.popitem(last=False)
    return value


def ratio(num: Tensor, den: Tensor) -> Tensor:
    """``num / den`` for ``den >= 0``: ``±inf`` by the sign of ``num`` where ``den == 0`` and
    ``0 / 0 = 0`` (never NaN)."""
    return torch.nan_to_num_(num / den, nan=0.0, posinf=torch.inf, neginf=-torch.inf)


def ratio_(num: Tensor, den: Tensor) -> Tensor:
    """:func:`ratio` computed in place in ``num`` (which must not be needed afterwards)."""
    return torch.nan_to_num_(num.div_(den), nan=0.0, posinf=torch.inf, neginf=-torch.inf)


def rescale_border_(stat: Tensor, count: Tensor, n: int, factor: Callable[[int], float]) -> Tensor:
    """Multiply ``stat`` in place by ``factor(n) / factor(count)`` where ``count != n`` (the
    border frame and no-data neighbourhoods); factors are evaluated once per distinct
    count. ``count`` broadcasts to ``stat``. Returns ``stat``."""
    if count.dim() == stat.dim() and count.dim() > 2 and count.stride()[0] == 0:
        count = count[(0,) * (count.dim() - 2)]  # a broadcast (H, W) count: work on one copy
    other = count != n
    if count.numel() == 0 or not bool(other.any()):
        return stat
    scale = torch.ones(count.shape, dtype=stat.dtype, device=stat.device)
    scale[other] = (factor(n) / factor_map(count[other], factor)).to(stat.dtype)
    return stat.mul_(scale)


def rescale_frame_(
    stat: Tensor, count: Tensor, r0: int, h: int, ring: Ring, factor: Callable[[int], float]
) -> Tensor:
    """:func:`rescale_border_` for a strip of rows ``r0 ..`` of an ``h``-row image without
    no-data: the counts are geometric, so only the frame of pixels within ``guard + train``
    of an edge (cut rings) is visited; ``count`` is the strip's ``(rows, W)`` ring count.
    Returns ``stat``."""
    rr, w = stat.shape[-2:]
    o = ring.outer
    left, right = min(o, w), max(w - o, o)
    lo, hi = max(0, min(o, h) - r0), min(rr, max(h - o, o) - r0)  # strip rows not in the frame
    pieces = [(slice(None), slice(0, left)), (slice(None), slice(right, w))]
    pieces += [
        (slice(0, max(lo, 0)), slice(left, right)),
        (slice(max(hi, 0), rr), slice(left, right)),
    ]
    for rows, cols in pieces:
        rescale_border_(stat[..., rows, cols], count[rows, cols], ring.n, factor)
    return stat


def border_scale(counts, n: int, factor: Callable[[int], float]) -> np.ndarray:
    """The border rule's factors as the compiled kernels read them: ``scale[c] = factor(n) /
    factor(c)`` (float64, rounded as :func:`rescale_border_` rounds it) for every count ``c``
    in ``counts`` other than ``0`` and ``n``, ``1`` elsewhere; length ``n + 1``."""
    scale = np.ones(n + 1)
    for c in counts:
        c = int(c)
        if 0 < c != n:  # ``float / tensor`` is ``reciprocal(tensor) * float`` in torch
            scale[c] = (1.0 / factor(c)) * factor(n)
    return scale


def geometric_scale(h: int, w: int, ring: Ring, factor: Callable[[int], float]) -> np.ndarray:
    """:func:`border_scale` for the ring counts of an ``h x w`` image without no-data."""
    return border_scale(ring_counts(h, w, ring), ring.n, factor)


def finish(statistic: Tensor, count: Tensor, dtype: torch.dtype) -> Tensor:
    """Cast the statistic to the output dtype and mark pixels without training cells
    (``count <= 0``) ``-inf``."""
    out = statistic.to(dtype)
    bad = count <= 0
    if not bool(bad.any()):  # the usual case: nothing to mark, skip a full-size pass
        return out
    return out.masked_fill(bad, -torch.inf)


def conclude(statistic: Tensor, vmask: Tensor | None, threshold: float) -> Detection:
    """The one ending of every CFAR: invalid cells under test get ``-inf``, then
    ``mask = statistic > threshold``."""
    if vmask is not None:
        statistic = statistic.masked_fill(~vmask.expand_as(statistic), -torch.inf)
    return detection_from(statistic, threshold)


def out_dtype(x: Tensor) -> torch.dtype:
    """The statistic dtype for input ``x`` (the library's dtype policy)."""
    return float_dtype(x.dtype)
