"""Two-parameter CFAR (seed eq. 1)."""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar import _jit, _triton
from torchsar._checks import check_image, check_positive, check_probability
from torchsar.cfar.core import (
    conclude,
    finish,
    one_sweep,
    out_dtype,
    prepare,
    ratio_,
    square_safe_planes,
    valid_planes,
)
from torchsar.cfar.thresholds import gaussian_factor
from torchsar.detection import WINDOW, Detection, DetectorSpec
from torchsar.windows import Ring, Sums, windowed

__all__ = ["two_parameter", "two_parameter_threshold"]


def two_parameter(
    x: Tensor,
    *,
    guard: int = 2,
    train: int = 4,
    pfa: float = 1e-3,
    k: float | None = None,
    valid: Tensor | None = None,
) -> Detection:
    """Two-parameter CFAR: statistic ``(I - mu_ring) / sigma_ring``, threshold ``K``.

    ``K = Phi^-1(1 - pfa)`` (Gaussian clutter assumption) unless ``k`` is given, as in the
    seed paper's eq. 1 (``(x_t - mu_c) / sigma_c > K_CFAR``). ``sigma_ring`` is the population
    standard deviation of the ring. A ring with zero variance gives ``+inf`` above the mean,
    ``-inf`` below it and ``0`` at it.

    Args:
        x: intensity ``(B, C, H, W)``, non-negative and finite.
        guard: guard half-width g.
        train: training-band width t.
        pfa: design probability of false alarm (used when ``k`` is None).
        k: explicit threshold ``K_CFAR`` (overrides ``pfa``).
        valid: optional bool mask of usable cells.

    Returns:
        :class:`Detection` with ``threshold = K``.

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        Novak, Owirka & Netishen, Lincoln Lab. J. 6(1), 1993; Nar, seed paper eq. 1.

    Examples:
        >>> x = torch.ones(1, 1, 16, 16); x[0, 0, 8, 8] = 5.0; x[0, 0, 0, 0] = 2.0
        >>> two_parameter(x, guard=1, train=2, k=3.0).mask[0, 0, 8, 8].item()
        True
    """
    ring, pfa, vmask = prepare(x, guard, train, pfa, valid, detector="two_parameter", values=False)
    thr = two_parameter_threshold(guard=guard, train=train, pfa=pfa, k=k)
    gpu = vmask is None and _triton.for_tensor(x)
    compiled = not gpu and _jit.for_tensor(x) and x.numel()
    if not compiled:  # the compiled kernel checks the values as it reads them
        check_image(x, "x")
    dtype = out_dtype(x)
    if compiled:
        return _one_sweep(x, ring, thr, dtype, vmask)

    def statistic(xs: Tensor, sums: list[Sums]) -> Tensor:
        s = sums[0]  # float64 strip sums of (x - shift), consumed in place below
        c = s.count.clamp_min(1)
        mean_c = s.s1.div_(c)  # ring mean of (x - shift)
        sigma = s.s2.div_(c).addcmul_(mean_c, mean_c, value=-1).clamp_min_(0).sqrt_()
        dev = xs.to(torch.float64, copy=True).sub_(s.shift).sub_(mean_c)
        return finish(ratio_(dev, sigma), s.count, dtype)

    stat = windowed(x, [ring.region], statistic, valid=vmask, moments=2)
    return conclude(stat, vmask, thr)


def _one_sweep(
    x: Tensor, ring: Ring, threshold: float, dtype: torch.dtype, vmask: Tensor | None
) -> Detection:
    """:func:`two_parameter` on the CPU in one sweep per image plane
    (:func:`torchsar._box_kernels.deviation_ratio`: the ring sums of ``x`` and its square
    summed directly, near-flat rings again from their cells; not shifted by the plane's mean
    as the tensor code's sums are, which a few bright targets far away would move). With
    no-data (``vmask``), the ring's valid cells are summed and counted alike; a pixel not
    valid itself, or with no valid ring cell, is ``-inf``."""
    from torchsar import _box_kernels

    planes, rescaled = square_safe_planes(x)
    if rescaled:  # a tiny negative value divided could read as -0.0
        check_image(x.detach(), "x")
    g, t = ring.guard, ring.train
    valid = valid_planes(vmask, x)

    def kernel(planes, thr, out, mask):
        return _box_kernels.deviation_ratio(planes, valid, vmask is not None, g, t, thr, out, mask)

    return one_sweep(x, planes, dtype, threshold, kernel)


def two_parameter_threshold(*, guard: int, train: int, pfa: float, k: float | None) -> float:
    """The design threshold ``K`` of :func:`two_parameter` for these options (no image
    needed): ``k`` when given, else ``Phi^-1(1 - pfa)``."""
    Ring(guard, train)
    if k is not None:
        return check_positive(k, "k", allow_zero=True)
    return gaussian_factor(check_probability(pfa, "pfa"))


SPEC = DetectorSpec(
    name="two_parameter",
    detect=two_parameter,
    order=1,
    options=WINDOW,
    threshold=two_parameter_threshold,
)
"""The registry entry of this detector (:class:`~torchsar.detection.DetectorSpec`)."""
