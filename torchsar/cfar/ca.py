"""Cell-averaging CFAR."""

from __future__ import annotations

import functools
from collections.abc import Callable
from functools import partial

import numpy as np
import torch
from torch import Tensor

from torchsar import _jit, _triton
from torchsar._checks import check_image, check_positive, check_probability
from torchsar.cfar.core import (
    border_scale,
    conclude,
    finish,
    geometric_scale,
    kernel_planes,
    one_sweep,
    out_dtype,
    prepare,
    ratio,
    rescale_border_,
    rescale_frame_,
    valid_planes,
)
from torchsar.cfar.thresholds import ca_factor
from torchsar.detection import WINDOW, Detection, DetectorSpec
from torchsar.windows import Ring, Sums, windowed

__all__ = ["ca", "ca_threshold", "count_scale", "kept_ring_ratio", "ring_mean_ratio"]


def ca(
    x: Tensor,
    *,
    guard: int = 2,
    train: int = 4,
    pfa: float = 1e-3,
    looks: float = 1.0,
    valid: Tensor | None = None,
) -> Detection:
    """Cell-averaging CFAR on intensity: statistic ``I / mean_ring``, threshold ``alpha``.

    ``alpha`` is exact for L-look gamma clutter (``looks=1``: exponential,
    ``alpha = N (pfa^(-1/N) - 1)``); see :func:`~torchsar.cfar.thresholds.ca_factor`.

    Args:
        x: intensity ``(B, C, H, W)``, non-negative and finite.
        guard: guard half-width g (the ``(2g+1)^2`` box around the cell under test is excluded).
        train: training-band width t; ``N = (2(g+t)+1)^2 - (2g+1)^2`` cells.
        pfa: design probability of false alarm.
        looks: number of looks L of the gamma clutter model.
        valid: optional bool mask of usable cells (no-data excluded from rings, never detected).

    Returns:
        :class:`Detection` with ``statistic = I / mean_ring`` (border pixels rescaled to the
        interior factor, see :mod:`torchsar.cfar.core`) and ``threshold = alpha(N)``.

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        Finn & Johnson, RCA Review 29, 1968; Gandhi & Kassam, IEEE TAES 24(4), 1988,
        doi:10.1109/7.7181.

    Examples:
        >>> x = torch.ones(1, 1, 16, 16); x[0, 0, 8, 8] = 100.0
        >>> ca(x, guard=1, train=2, pfa=1e-3).mask.sum().item()
        1
    """
    ring, pfa, vmask = prepare(x, guard, train, pfa, valid, detector="ca", values=False)
    factor = partial(ca_factor, pfa=pfa, looks=check_positive(looks, "looks"))
    threshold = ca_threshold(guard=guard, train=train, pfa=pfa, looks=looks)
    gpu = vmask is None and _triton.for_tensor(x)
    compiled = not gpu and _jit.for_tensor(x) and x.numel()
    if not compiled:  # the compiled kernels check the values as they read them
        check_image(x, "x")
    if gpu:
        stat, mask = _gpu_ring_ratio(x, ring, factor, threshold)
        return Detection(mask=mask, statistic=stat, threshold=_threshold(threshold, stat))
    if compiled and vmask is not None:
        scale = count_scale(ring.n, pfa, check_positive(looks, "looks"))
        return kept_ring_ratio(x, ring, vmask, scale, threshold, out_dtype(x))
    if compiled:
        return _compiled_ring_ratio(x, ring, factor, out_dtype(x), threshold)
    stat = ring_mean_ratio(x, ring, factor, vmask, out_dtype(x))
    return conclude(stat, vmask, threshold)


def ring_mean_ratio(
    x: Tensor, ring: Ring, factor: Callable[[int], float], vmask: Tensor | None, dtype: torch.dtype
) -> Tensor:
    """``I / mean_ring`` over the counted ring cells, with the border rule of
    :mod:`torchsar.cfar.core` for the factor ``factor(n)``, in ``dtype`` (CA's statistic;
    AC uses it on its censored ring). Without a mask every ring holds cells and the counts
    are geometric: the mean is formed in place and only the frame is rescaled."""
    if vmask is None and dtype == torch.float32 and _triton.for_tensor(x):
        return _gpu_ring_ratio(x, ring, factor, torch.inf)[0]
    if vmask is None and _jit.for_tensor(x) and x.numel():
        return _compiled_ring_ratio(x, ring, factor, dtype, torch.inf).statistic
    h = x.shape[-2]
    row = torch.arange(h, device=x.device).view(h, 1)  # sliced with the strip: its rows

    def statistic(xs: Tensor, sums: list[Sums], rows: Tensor) -> Tensor:
        s = sums[0]
        if vmask is None:
            stat = ratio(xs, s.s1.div_(s.count).add_(s.shift))  # float64 by promotion
            r0 = int(rows[0, 0]) if rows.numel() else 0
            return rescale_frame_(stat, s.count, r0, h, ring, factor).to(dtype)
        stat = ratio(xs, s.mean_())
        return finish(rescale_border_(stat, s.count, ring.n, factor), s.count, dtype)

    return windowed(x, [ring.region], statistic, valid=vmask, moments=1, extras=(row,))


def _compiled_ring_ratio(
    x: Tensor, ring: Ring, factor: Callable[[int], float], dtype: torch.dtype, threshold: float
) -> Detection:
    """:func:`ring_mean_ratio` without a mask and the decision ``statistic > threshold`` in
    one sweep per image plane (:func:`torchsar._box_kernels.ring_ratio`: block sums of
    non-negative terms, within a float32 ulp of the exact mean; the border factors once per
    ring size that occurs)."""
    from torchsar import _box_kernels

    g, t, scale = ring.guard, ring.train, geometric_scale(*x.shape[-2:], ring, factor)
    return one_sweep(
        x,
        kernel_planes(x),
        dtype,
        threshold,
        lambda planes, thr, out, mask: _box_kernels.ring_ratio(planes, g, t, scale, thr, out, mask),
    )


def kept_ring_ratio(
    x: Tensor,
    ring: Ring,
    vmask: Tensor | None,
    scale: np.ndarray,
    threshold: float,
    dtype: torch.dtype,
    censor: tuple[Tensor, Tensor] | None = None,
    global_factor: float = 0.0,
) -> Detection:
    """``x / mean`` over the ring's kept cells and the decision in one sweep per image plane
    on the CPU (:func:`torchsar._box_kernels.kept_ratio`: the kept cells and their count
    summed directly, as the one-sweep CA sums its ring): the valid cells (``vmask``), and
    with ``censor`` (AC-CFAR's pre-threshold and clutter mean per plane, ``(B, C, 1, 1)``)
    those at or below the pre-threshold, a ring with none taking ``(x / mu)
    global_factor``; without ``censor`` such a ring gives ``-inf``, as a pixel not valid
    itself does. ``scale[c]``: the border rule's factor of a ring of ``c`` kept cells
    (:func:`count_scale`)."""
    from torchsar import _box_kernels

    p = x.shape[0] * x.shape[1]
    if censor is None:
        limit, mu = np.full(p, np.inf), np.full(p, np.nan)
    else:
        limit, mu = (c.to(torch.float64).reshape(-1).contiguous().numpy() for c in censor)
    valid, g, t = valid_planes(vmask, x), ring.guard, ring.train

    def kernel(planes, thr, out, mask):
        return _box_kernels.kept_ratio(
            planes, valid, vmask is not None, limit, mu, g, t, scale, global_factor, thr, out, mask
        )

    return one_sweep(x, kernel_planes(x), dtype, threshold, kernel)


@functools.lru_cache(maxsize=32)
def count_scale(n: int, pfa: float, looks: float) -> np.ndarray:
    """The border rule's factors ``factor(n) / factor(c)`` of a ring of every count ``c =
    0 .. n`` (as :func:`torchsar.cfar.core.border_scale` rounds them), CA's factor."""
    return border_scale(range(n + 1), n, partial(ca_factor, pfa=pfa, looks=looks))


def _gpu_ring_ratio(
    x: Tensor, ring: Ring, factor: Callable[[int], float], threshold: float
) -> tuple[Tensor, Tensor]:
    """:func:`_compiled_ring_ratio` on a GPU: the fused Triton kernel
    (:func:`torchsar._gpu_kernels.ring_ratio`, float32, every ring summed directly in
    float64: within a float32 ulp of the CPU's statistic)."""
    scale = geometric_scale(*x.shape[-2:], ring, factor)
    thr = _threshold(threshold, x)
    return _triton.kernels().ring_ratio(x, ring.guard, ring.train, scale, thr)


def _threshold(threshold: float, statistic: Tensor) -> Tensor:
    """The threshold as :func:`~torchsar.detection.detection_from` holds it: a scalar
    tensor of the statistic's dtype."""
    return torch.as_tensor(threshold, dtype=statistic.dtype, device=statistic.device)


def ca_threshold(*, guard: int, train: int, pfa: float, looks: float) -> float:
    """The design threshold ``alpha(N)`` of :func:`ca` for these options (no image needed)."""
    n = Ring(guard, train).n
    return ca_factor(n, check_probability(pfa, "pfa"), check_positive(looks, "looks"))


SPEC = DetectorSpec(name="ca", detect=ca, order=0, options=WINDOW, threshold=ca_threshold)
"""The registry entry of this detector (:class:`~torchsar.detection.DetectorSpec`)."""
