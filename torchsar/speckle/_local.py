"""Shared machinery of the speckle filters: entry checks, the speckle model constants and
the local statistics (box mean and coefficient of variation) of every filter.

Border rule: the window statistics (mean, population variance, ``Ci``) are taken over the
window cells that lie inside the image (:func:`torchsar.windows.windowed` counting), so a
border pixel gets the textbook statistic of its truncated window and interior pixels are
exact. ``Ci = sigma / mu`` with the population standard deviation; a window with zero mean
(all zeros, since intensity is non-negative) has ``Ci = 0``.

Scale: every filter is scale-equivariant (``filter(s x) = s filter(x)``); an image plane
whose peak is so large (or small) that squares and window sums would overflow (or
underflow) its dtype is filtered divided by a power of two and scaled back, which is exact.
Planes of ordinary magnitude are filtered as they are.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from torchsar import _jit
from torchsar._checks import check_image, check_odd, check_positive, check_window_fits, float_dtype
from torchsar._scale import power_of_two
from torchsar.errors import InputValueError, OptionError
from torchsar.windows import Rect, Sums, windowed

__all__ = [
    "Compiled",
    "Request",
    "Speckle",
    "decay_map",
    "filter_intensity",
    "finish",
    "local_moments",
    "prepare",
    "scratch",
    "sqrt",
]


@dataclass(frozen=True)
class Speckle:
    """Fully developed L-look speckle: ``Cu^2 = 1 / L`` and ``Cmax^2 = 1 + 2 / L``."""

    looks: float

    @property
    def cu2(self) -> float:
        """Squared coefficient of variation of the speckle, ``1 / L``."""
        return 1.0 / self.looks

    @property
    def cmax2(self) -> float:
        """Squared upper heterogeneity bound (Lopes et al. 1990), ``1 + 2 / L``."""
        return 1.0 + 2.0 / self.looks

    def heterogeneity(self, ci2: Tensor, damping: float) -> Tensor:
        """The three classes of the enhanced filters as one number per pixel:
        ``damping (Ci - Cu) / (Cmax - Ci)`` for ``Cu < Ci < Cmax`` (textured), 0 for
        ``Ci <= Cu`` (homogeneous: the window mean) and ``inf`` for ``Ci >= Cmax`` (point
        target: the observation). Consumes ``ci2``."""
        cu, cmax = self.cu2**0.5, self.cmax2**0.5
        ci = sqrt(ci2)
        h = (ci - cu).clamp_min_(0).mul_(damping).div_(cmax - ci)
        return h.masked_fill_(ci >= cmax, torch.inf)


@dataclass(frozen=True)
class Request:
    """A validated filter call: intensity image, window radius, speckle model, output form."""

    intensity: Tensor
    radius: int
    speckle: Speckle
    amplitude: bool
    dtype: torch.dtype
    damping: float | None = None
    scale: Tensor | None = None  # (B, C, 1, 1) powers of two the input was divided by
    unchecked: Tensor | None = None  # the input, when its values are left to the kernel


def _plane_scale(x: Tensor) -> Tensor | None:
    """Per-plane powers of two ``(B, C, 1, 1)`` bringing the peak of every plane whose peak
    lies outside ``[2^-e, 2^e]`` (``e = 3/8`` of the dtype's exponent range: 48 for float32)
    into ``[1, 2)``, 1 for the other planes; None when no plane needs it."""
    if x.numel() == 0:
        return None
    e = 48 if x.dtype == torch.float32 else 384  # 3/8 of the largest exponent (128, 1024)
    peak = x.detach().amax(dim=(-2, -1), keepdim=True)  # validated: no negative value
    outside = (peak > 2.0**e) | ((peak > 0) & (peak < 2.0**-e))
    if not bool(outside.any()):
        return None
    return torch.where(outside, power_of_two(peak), 1.0)


def prepare(
    x: Tensor,
    window: int,
    looks: float,
    amplitude: bool,
    damping: float | None = None,
    *,
    kernel: bool = False,
) -> Request:
    """Validate the filter arguments (``damping`` only when given) and convert amplitude to
    intensity. ``kernel``: the filter has a one-sweep kernel, which works in float64, so a
    float32 intensity it will take needs no rescaling against overflow, and which checks
    the values of an intensity as it reads them (:func:`run_kernel`). The values are
    checked after the options on every path, so a call with a bad option and a bad value
    gets the same error with or without the kernels."""
    x_ = x.detach() if isinstance(x, Tensor) else x
    check_image(x_, "x", values=False)  # the values last, after the cheap checks
    window = check_odd(window, "window", minimum=3)
    check_window_fits(x, window, "speckle filter")
    looks = check_positive(looks, "looks")
    if not isinstance(amplitude, bool):
        raise OptionError(f"amplitude must be a bool, got {amplitude!r}")
    if damping is not None:
        damping = check_positive(damping, "damping", allow_zero=True)
    in_kernel = kernel and not amplitude and takes_kernel(x)
    if not in_kernel:
        check_image(x_, "x")
    dtype = float_dtype(x.dtype)
    xi = x.to(dtype)
    scale = None if in_kernel and xi.dtype == torch.float32 else _plane_scale(xi)
    if in_kernel and scale is not None:  # rescaled, a tiny negative would read as -0.0
        check_image(x_, "x")
        in_kernel = False
    if scale is not None:
        xi = xi / scale  # exact: a power of two
    intensity = xi.square() if amplitude else xi
    unchecked = x if in_kernel else None
    return Request(
        intensity, window // 2, Speckle(looks), amplitude, dtype, damping, scale, unchecked
    )


def takes_kernel(x: Tensor) -> bool:
    """Whether a filter with a one-sweep kernel runs it on ``x``."""
    return _jit.for_tensor(x) and x.numel() > 0


def run_kernel(req: Request, kernel: Callable[[np.ndarray, np.ndarray], int]) -> Tensor:
    """``kernel(planes, out)`` on the ``(P, H, W)`` planes of ``req.intensity`` into a new
    tensor of its shape and dtype. The kernel returns how many input values are not a
    finite number ``>= 0`` (it checks them as it reads them, for :func:`prepare`): any, and
    the error about the caller's input is raised as
    :func:`~torchsar._checks.check_image` words it."""
    x = req.intensity
    h, w = x.shape[-2:]
    planes = x.detach().resolve_neg().reshape(-1, h, w).contiguous().numpy()
    out = torch.empty(x.shape, dtype=x.dtype)
    if kernel(planes, out.numpy().reshape(planes.shape)):
        check_image(x.detach() if req.unchecked is None else req.unchecked.detach(), "x")
        raise InputValueError("x must be finite and non-negative")  # not reached
    return out


def finish(req: Request, intensity: Tensor, *, nonnegative: bool = False) -> Tensor:
    """The filtered image in the caller's form (square root back to amplitude if asked,
    times the scale the input was divided by); ``nonnegative``: ``intensity`` is known to
    be (the kernels'), so it is not clamped at 0 again."""
    out = intensity if nonnegative else intensity.clamp_min_(0)
    out = sqrt(out) if req.amplitude else out
    if req.scale is None:
        return out
    return (out * req.scale).clamp_max(torch.finfo(out.dtype).max)


def scratch(t: Tensor) -> Tensor:
    """``t`` itself, free to be overwritten in place, or a copy of it when autograd records
    ``t`` (its graph may have saved the values an in-place update would overwrite)."""
    return t.clone() if t.requires_grad else t


def sqrt(t: Tensor) -> Tensor:
    """Square root of ``t >= 0``, in place unless autograd records ``t``; then its gradient
    at 0 is 0 instead of ``inf`` (a constant window has no direction of steepest change)."""
    if not t.requires_grad:
        return t.sqrt_()
    pos = t > 0
    return torch.where(pos, torch.where(pos, t, 1.0).sqrt(), 0.0)


def local_moments(s: Sums, dtype: torch.dtype = torch.float64) -> tuple[Tensor, Tensor]:
    """Window mean ``mu`` (clamped >= 0) and ``Ci^2 = var / mu^2`` (0 where ``mu = 0``),
    computed in float64 from the window sums (which it consumes: ``s.s1`` and ``s.s2`` are
    overwritten) and returned in ``dtype``.

    ``Ci^2`` is clamped to ``count - 1``, its mathematical bound for non-negative data, so
    rounding in windows of (near-)zero mean can never produce Inf or NaN downstream.
    """
    if s.s2 is None:
        raise ValueError("local_moments needs second moments (moments=2)")
    inv = s.count.clamp_min(1).reciprocal()
    m1 = s.s1.mul_(inv)
    var = s.s2.mul_(inv).addcmul_(m1, m1, value=-1.0).clamp_min_(0)
    mu = scratch(m1).add_(s.shift).clamp_min_(0)
    mu2 = mu.square()
    if mu2.requires_grad:  # keep 0 / 0 out of the graph (its gradient would be NaN)
        mu2 = torch.where(mu2 > 0, mu2, 1.0)
    ci2 = var.div_(mu2).nan_to_num_(nan=0.0)
    ci2 = ci2.clamp_max_((s.count - 1).clamp_min(0))
    return mu.to(dtype), ci2.to(dtype)


Formula = Callable[[Tensor, Tensor, Tensor], Tensor]


@dataclass(frozen=True)
class Compiled:
    """A box-statistics formula the one-sweep kernel knows
    (:func:`torchsar._box_kernels.box_filter`): Lee / Kuan (``weight_scale`` 1 or
    ``1 + Cu^2``) or, ``enhanced``, enhanced Lee; and its constants."""

    enhanced: bool
    cu2: float
    weight_scale: float = 1.0
    damping: float = 0.0
    cmax2: float = 0.0


def filter_intensity(req: Request, formula: Formula, compiled: Compiled | None = None) -> Tensor:
    """Run ``formula(I, mu, Ci^2)`` over the image, strip by strip, in ``req.dtype``.

    This is the whole pipeline of the box-statistics filters (Lee, Kuan, enhanced Lee,
    Gamma-MAP): one :func:`~torchsar.windows.windowed` pass computes the window moments from
    float64 integral images (mean and ``Ci^2`` in float64, then cast) and applies the
    per-pixel formula in the output dtype. With ``compiled`` (the same formula in the
    kernel's terms), CPU tensors without gradients take the one-sweep kernel instead: direct
    window sums and the formula in float64, cast once (within a float32 ulp or two of this
    path; tested).
    """
    x = req.intensity
    if compiled is not None and takes_kernel(x):
        return finish(req, _compiled_filter(req, compiled), nonnegative=True)

    def apply(xs: Tensor, sums: list[Sums]) -> Tensor:
        mu, ci2 = local_moments(sums[0], req.dtype)
        return formula(xs, mu, ci2)

    out = windowed(req.intensity, [Rect.box(req.radius)], apply, moments=2)
    return finish(req, out)


def _compiled_filter(req: Request, k: Compiled) -> Tensor:
    """:func:`filter_intensity`'s formula by :func:`torchsar._box_kernels.box_filter`."""
    from torchsar import _box_kernels

    r = req.radius
    return run_kernel(
        req,
        lambda planes, out: _box_kernels.box_filter(
            planes, r, k.enhanced, k.cu2, k.weight_scale, k.damping, k.cmax2, out
        ),
    )


def decay_map(req: Request, decay: Callable[[Tensor], Tensor]) -> Tensor:
    """Full-size ``decay(Ci^2)`` in ``req.dtype``, evaluated strip by strip (for the
    Frost-type filters' per-pixel weight decay)."""

    def apply(_xs: Tensor, sums: list[Sums]) -> Tensor:
        return decay(local_moments(sums[0], req.dtype)[1])

    return windowed(req.intensity, [Rect.box(req.radius)], apply, moments=2)
