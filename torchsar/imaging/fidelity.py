"""Fidelity of an image or phase estimate to the truth, modulo what the data cannot observe.

For simulations with a known scene and phase error: a constant and linear phase error (a
circular image shift) cannot be observed, and for 2-D errors optionally neither can the twin
image (``conj(f(-r))``, the flip ambiguity of phase retrieval). :func:`align` and
:func:`magnitude_correlation` compare images up to that shift (and flip); :func:`phase_rmse`
compares phase estimates after :func:`remove_linear_phase`.

How well focused an image is without a reference: :mod:`torchsar.imaging.focus`.
"""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar._checks import check_same_shape
from torchsar._scale import unit_scale
from torchsar.errors import InputValueError, ShapeError

__all__ = ["align", "magnitude_correlation", "phase_rmse", "remove_linear_phase"]


def _standardise(a: Tensor) -> Tensor:
    """Each plane centred and scaled to unit norm; divided first by a power of two near its
    peak (exact), so the squares in the norm cannot overflow."""
    a = a.flatten(-2)
    a = a / unit_scale(a, dims=1)
    a = a - a.mean(-1, keepdim=True)
    return a / a.norm(dim=-1, keepdim=True).clamp_min(torch.finfo(a.dtype).tiny)


def _circular_xcorr(a: Tensor, b: Tensor) -> Tensor:
    """Pearson correlation of ``b`` with ``a`` circularly shifted by every ``(dr, dc)``."""
    h, w = a.shape[-2:]
    sa, sb = _standardise(a).unflatten(-1, (h, w)), _standardise(b).unflatten(-1, (h, w))
    return torch.fft.ifft2(torch.fft.fft2(sb) * torch.fft.fft2(sa).conj()).real


def align(estimate: Tensor, reference: Tensor, *, flip: bool = False) -> tuple[Tensor, Tensor]:
    """Circularly shift (and optionally flip) ``estimate`` to best match ``reference``.

    Both are real ``(B, C, H, W)`` (e.g. magnitudes). The shift maximises the Pearson
    correlation; with ``flip`` the 180-degree-rotated estimate (twin image) is also tried.

    Returns:
        ``(aligned estimate, correlation (B, C))``.

    Examples:
        >>> ref = torch.zeros(1, 1, 4, 4); ref[0, 0, 1, 2] = 1
        >>> est, c = align(ref.roll(1, dims=-1), ref)
        >>> bool(torch.equal(est, ref)), round(float(c), 4)
        (True, 1.0)
    """
    check_same_shape(estimate, reference, "estimate", "reference")
    cands = [estimate, estimate.flip(-2, -1)] if flip else [estimate]
    best, best_c = estimate, None
    for cand in cands:
        xc = _circular_xcorr(cand, reference)
        c, idx = xc.flatten(-2).max(-1)
        w = xc.shape[-1]
        shifted = _roll_each(cand, idx // w, idx % w)
        if best_c is None:
            best, best_c = shifted, c
        else:
            take = (c > best_c)[..., None, None]
            best, best_c = torch.where(take, shifted, best), torch.maximum(c, best_c)
    return best, best_c


def _roll_each(x: Tensor, dr: Tensor, dc: Tensor) -> Tensor:
    """Circularly roll every ``(H, W)`` plane by its own ``(dr, dc)``."""
    h, w = x.shape[-2:]
    rows = (torch.arange(h, device=x.device) - dr[..., None]) % h  # (..., H)
    cols = (torch.arange(w, device=x.device) - dc[..., None]) % w
    x = torch.gather(x, -2, rows[..., :, None].expand(*x.shape))
    return torch.gather(x, -1, cols[..., None, :].expand(*x.shape))


def magnitude_correlation(estimate: Tensor, reference: Tensor, *, flip: bool = False) -> Tensor:
    """Pearson correlation of ``|estimate|`` and ``|reference|`` after the best circular shift.

    Args:
        estimate: complex or real image ``(B, C, H, W)``.
        reference: complex or real image, same shape (the true reflectivity).
        flip: also accept the twin (180-degree-rotated) image.

    Returns:
        ``(B, C)`` in ``[-1, 1]``.

    Examples:
        >>> f = torch.zeros(1, 1, 8, 8, dtype=torch.complex64); f[0, 0, 2, 3] = 1j
        >>> round(float(magnitude_correlation(f.roll(3, -2), f)), 4)
        1.0
    """
    return align(estimate.abs(), reference.abs(), flip=flip)[1]


def remove_linear_phase(phi: Tensor) -> Tensor:
    """Wrap a phase difference and remove its constant and linear parts (unobservable).

    Works on ``(B, M)`` (linear in ``m``) or ``(B, M, K)`` (linear in ``m`` and ``k``). The
    slopes come from the mean phase increment along each axis, the constant from the circular
    mean; a final least-squares plane fit on the (now small) wrapped residual refines them.

    Examples:
        >>> m = torch.arange(8.0)[None]
        >>> float(remove_linear_phase(0.3 + 0.7 * m).abs().max()) < 1e-5
        True
    """
    z = torch.polar(torch.ones_like(phi), phi)
    axes = [-1] if phi.dim() == 2 else [-2, -1]
    for ax in axes:
        inc = z.narrow(ax, 1, z.shape[ax] - 1) * z.narrow(ax, 0, z.shape[ax] - 1).conj()
        slope = inc.flatten(1).sum(-1).angle()
        z = z * torch.polar(torch.ones_like(phi), -_ramp(phi, ax) * _bcast(slope, phi))
    const = z.flatten(1).sum(-1).angle()
    resid = (z * torch.polar(torch.ones_like(phi), -_bcast(const, phi))).angle()
    return _remove_plane(resid, axes)


def _ramp(phi: Tensor, ax: int) -> Tensor:
    n = phi.shape[ax]
    shape = [1] * phi.dim()
    shape[ax] = n
    return torch.arange(n, dtype=phi.dtype, device=phi.device).reshape(shape)


def _bcast(v: Tensor, like: Tensor) -> Tensor:
    return v.reshape(-1, *([1] * (like.dim() - 1)))


def _remove_plane(r: Tensor, axes: list[int]) -> Tensor:
    """Subtract the least-squares fit of ``1`` and ramps along ``axes`` (per item)."""
    cols = [torch.ones_like(r)] + [_ramp(r, ax).expand_as(r) for ax in axes]
    a = torch.stack([c.flatten(1) for c in cols], -1)  # (B, N, P)
    if a.shape[1] < a.shape[2]:
        return r
    coef = torch.linalg.lstsq(a, r.flatten(1)[..., None]).solution
    return (r.flatten(1) - (a @ coef)[..., 0]).reshape(r.shape)


def phase_rmse(estimate: Tensor, truth: Tensor) -> Tensor:
    """RMS phase error (radians) after removing constant and linear parts, wrapped.

    Args:
        estimate: ``(B, M)`` or ``(B, M, K)``.
        truth: same shape.

    Returns:
        ``(B,)``.

    Raises:
        ShapeError: shapes differ or are not 2-D / 3-D.
        InputValueError: non-finite values.

    Examples:
        >>> t = torch.rand(2, 16) * 6
        >>> float(phase_rmse(t + 1.0 + 0.2 * torch.arange(16.0), t).max()) < 1e-4
        True
    """
    if not isinstance(estimate, Tensor) or not isinstance(truth, Tensor):
        raise ShapeError("estimate and truth must be tensors")
    check_same_shape(estimate, truth, "estimate", "truth")
    if estimate.dim() not in (2, 3):
        raise ShapeError(f"phases must be (B, M) or (B, M, K), got {tuple(estimate.shape)}")
    d = (estimate - truth).to(torch.float64)
    if not bool(torch.isfinite(d).all()):
        raise InputValueError("estimate and truth must be finite")
    if d.numel() == 0:
        return d.new_zeros(d.shape[0])
    r = remove_linear_phase(d)
    return r.square().flatten(1).mean(-1).sqrt().to(estimate.dtype)
