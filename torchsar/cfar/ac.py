"""Automatic-censoring CFAR (after Gao et al. 2009)."""

from __future__ import annotations

import math
from functools import partial

import torch
from torch import Tensor

from torchsar import _jit, _triton
from torchsar._checks import check_image, check_int, check_positive, check_probability
from torchsar.cfar.ca import ca_threshold, count_scale, kept_ring_ratio, ring_mean_ratio
from torchsar.cfar.core import (
    conclude,
    out_dtype,
    prepare,
    ratio,
)
from torchsar.cfar.thresholds import ca_factor
from torchsar.detection import WINDOW, Detection, DetectorSpec
from torchsar.windows import Ring

__all__ = ["ac", "ac_threshold", "global_censor_threshold"]


def ac(
    x: Tensor,
    *,
    guard: int = 2,
    train: int = 4,
    pfa: float = 1e-3,
    censor_pfa: float | None = None,
    iterations: int = 3,
    valid: Tensor | None = None,
    clutter_mean: float | None = None,
) -> Detection:
    """Automatic-censoring CFAR: censor likely targets from the ring, then CA on the rest.

    Procedure (Gao et al. 2009, steps 1-2, with the exponential clutter model of this family):

    1. **Global adaptive pre-threshold** per image and channel
       (:func:`global_censor_threshold`): ``T = mu * ln(1 / censor_pfa)``, the
       ``1 - censor_pfa`` quantile of exponential clutter of mean ``mu``, where ``mu`` is
       re-estimated ``iterations`` times from the pixels below the current ``T`` (the mean of
       an exponential truncated at its ``1 - p`` quantile, divided by its known ratio to the
       full mean). Pixels above ``T`` form the index matrix of potential targets.
    2. **Censored ring statistics**: the potential-target pixels are removed from every ring
       through the ``valid`` mask of :func:`~torchsar.windows.windowed` (masked integral
       images), giving the censored mean ``m`` over the ``n <= N`` remaining cells.
    3. **Test**: statistic ``I / m`` rescaled by ``ca_factor(N) / ca_factor(n)`` (the core's
       border rule, here also covering censored cells), threshold ``ca_factor(N)``. A ring
       with every cell censored falls back to the global clutter mean ``mu`` with the
       known-mean factor ``ln(1 / pfa)``.

    Gao et al. fit the G0 law to the censored ring; this variant keeps the exponential model
    so that it shares the family's calibrated factors (use :func:`~torchsar.cfar.g0` for G0).
    The cell under test is never censored from its own test.

    Args:
        x: intensity ``(B, C, H, W)``, non-negative and finite.
        guard: guard half-width g.
        train: training-band width t.
        pfa: design probability of false alarm.
        censor_pfa: false-alarm rate of the global pre-threshold (default: ``pfa``).
        iterations: re-estimations of the global clutter mean (>= 0).
        valid: optional bool mask of usable cells.
        clutter_mean: the global clutter mean ``mu`` of step 1, given instead of estimated
            from ``x`` (finite, >= 0). For ``x`` a piece of a larger image: the tiled
            runner (:mod:`torchsar.tiling`) estimates it over the whole scene, so every tile
            is censored as the whole image would be.

    Returns:
        :class:`Detection` with ``threshold = ca_factor(N, pfa)``.

    Raises:
        InputTypeError, ShapeError, InputValueError, WindowSizeError, OptionError: bad input.

    Shape:
        ``(B, C, H, W)`` in, ``(B, C, H, W)`` out.

    References:
        Gao, G., Liu, L., Zhao, L., Shi, G., Kuang, G., An adaptive and fast CFAR algorithm
        based on automatic censoring for target detection in high-resolution SAR images,
        IEEE TGRS 47(6), 1685-1697, 2009, doi:10.1109/TGRS.2008.2006504.

    Examples:
        >>> x = torch.ones(1, 1, 16, 16); x[0, 0, 8, 8] = 20.0; x[0, 0, 5, 5:12] = 100.0
        >>> ac(x, guard=1, train=2).mask[0, 0, 8, 8].item()  # the bright row is censored
        True
        >>> ts.cfar.ca(x, guard=1, train=2).mask[0, 0, 8, 8].item()  # CA is masked by it
        False
    """
    ring, pfa, vmask = prepare(x, guard, train, pfa, valid, detector="ac", values=False)
    p_c = pfa if censor_pfa is None else check_probability(censor_pfa, "censor_pfa")
    iterations = check_int(iterations, "iterations", minimum=0)
    if clutter_mean is not None:
        check_positive(clutter_mean, "clutter_mean", allow_zero=True)
    compiled = not _triton.for_tensor(x) and _jit.for_tensor(x) and x.numel()
    if not compiled:  # the values last, after every option (the compiled kernel reads them)
        check_image(x, "x")
    if clutter_mean is None:
        mu, thr = global_censor_threshold(x, p_c, iterations=iterations, valid=vmask)
    else:
        given = check_positive(clutter_mean, "clutter_mean", allow_zero=True)
        mu = x.new_full((*x.shape[:2], 1, 1), given, dtype=torch.float64)
        thr = mu * math.log(1.0 / p_c)
    alpha = ac_threshold(
        guard=guard, train=train, pfa=pfa, censor_pfa=censor_pfa, iterations=iterations
    )
    dtype = out_dtype(x)
    if compiled:
        return _one_sweep(x, ring, pfa, (thr, mu), alpha, dtype, vmask)
    keep = x <= thr if vmask is None else vmask & (x <= thr)
    stat = ring_mean_ratio(x, ring, partial(ca_factor, pfa=pfa), keep, dtype)
    glob = ratio(x.to(torch.float64), mu) * (alpha / math.log(1.0 / pfa))
    stat = torch.where(stat == -torch.inf, glob.to(dtype), stat)  # fully censored rings
    return conclude(stat, vmask, alpha)


def _one_sweep(
    x: Tensor,
    ring: Ring,
    pfa: float,
    censor: tuple[Tensor, Tensor],
    alpha: float,
    dtype: torch.dtype,
    vmask: Tensor | None,
) -> Detection:
    """:func:`ac` on the CPU in one sweep per image plane
    (:func:`torchsar.cfar.ca.kept_ring_ratio`: the censored ring's cells, valid ones with
    no-data, and their count summed directly, as CA sums its ring); ``censor``: each
    plane's pre-threshold and clutter mean ``(B, C, 1, 1)``."""
    scale = count_scale(ring.n, pfa, 1.0)
    factor = alpha / math.log(1.0 / pfa)
    return kept_ring_ratio(x, ring, vmask, scale, alpha, dtype, censor, factor)


def ac_threshold(
    *, guard: int, train: int, pfa: float, censor_pfa: float | None, iterations: int
) -> float:
    """The design threshold of :func:`ac` for these options: the interior CA factor (the
    censoring options are only validated)."""
    if censor_pfa is not None:
        check_probability(censor_pfa, "censor_pfa")
    check_int(iterations, "iterations", minimum=0)
    return ca_threshold(guard=guard, train=train, pfa=pfa, looks=1.0)


def global_censor_threshold(
    x: Tensor, censor_pfa: float, *, iterations: int = 3, valid: Tensor | None = None
) -> tuple[Tensor, Tensor]:
    """Per-image clutter mean ``mu`` and pre-threshold ``T = mu ln(1/p)``, ``(B, C, 1, 1)``.

    ``mu`` starts as the image mean; each iteration takes the mean of the (valid) pixels at or
    below ``T`` and divides it by ``E[X | X <= T] / E[X] = 1 - p ln(1/p) / (1 - p)``, the
    truncated-exponential ratio, so homogeneous clutter gives an unbiased ``mu``. Without
    ``valid``, a CPU tensor takes one compiled pass per estimate
    (:func:`torchsar.cfar._kernels.censor_mean`; the same rule, summed in another order).

    Examples:
        >>> x = torch.empty(1, 1, 256, 256).exponential_(generator=torch.Generator().manual_seed(0))
        >>> mu, t = global_censor_threshold(x, 1e-3)
        >>> abs(mu.item() - 1.0) < 0.02
        True
    """
    q = math.log(1.0 / censor_pfa)
    ratio_kept = 1.0 - censor_pfa * q / (1.0 - censor_pfa)
    if valid is None and _jit.for_tensor(x) and x.numel():
        from torchsar.cfar import _kernels

        planes = (
            x.detach()
            .resolve_neg()
            .reshape(*x.shape[:2], -1)
            .reshape(-1, x.shape[-2] * x.shape[-1])
        )
        mu = _kernels.censor_mean(planes.contiguous().numpy(), q, ratio_kept, iterations)
        mu = torch.from_numpy(mu).reshape(*x.shape[:2], 1, 1)
        return mu, mu * q
    m = torch.ones_like(x, dtype=torch.bool) if valid is None else valid.expand_as(x)
    xd = x.to(torch.float64)
    mu = _masked_mean(xd, m)
    for _ in range(iterations):
        mu = _masked_mean(xd, m & (xd <= mu * q)) / ratio_kept
    return mu, mu * q


def _masked_mean(x: Tensor, m: Tensor) -> Tensor:
    num = (x * m).sum(dim=(-2, -1), keepdim=True)
    return num / m.sum(dim=(-2, -1), keepdim=True).clamp_min(1)


SPEC = DetectorSpec(
    name="ac",
    detect=ac,
    order=6,
    options={**WINDOW, "censor_pfa": None, "iterations": 3},
    threshold=ac_threshold,
)
"""The registry entry of this detector (:class:`~torchsar.detection.DetectorSpec`)."""
