"""1-D autofocus on per-pulse image decompositions (backprojection imagery).

With per-pulse images ``b_m = C_m^H g_m`` (:meth:`BackprojectionOperator.pulse_images`) the
phase-corrected image is ``y(phi) = sum_m exp(-1j phi_m) b_m`` and the closed-form phase step
of sparsity-driven autofocus is exact without any forward operator:
``phi_m = angle(<C_m f, g_m>) = angle(sum_p conj(f_p) b_m[p])``. The image step uses the
matched-filter approximation ``C^H C ~ I`` (the operator is scaled so its Gram diagonal is 1),
i.e. ``f = 2 y / (2 + p lam Lambda(f))``.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar._checks import check_complex, check_int, check_positive
from torchsar._scale import unit_scale
from torchsar.errors import OptionError
from torchsar.imaging._dtypes import as_complex
from torchsar.imaging.focus import entropy_terms
from torchsar.imaging.items import nonzero_items
from torchsar.imaging.min_entropy import entropy_result, lbfgs_phases
from torchsar.imaging.result import AutofocusResult, MinEntropyResult, fill_result

__all__ = ["pulse_autofocus", "pulse_min_entropy"]


def _form(b: Tensor, phi: Tensor) -> Tensor:
    """``sum_m exp(-1j phi_m) b_m``: ``(B, M, H, W), (B, M) -> (B, 1, H, W)``."""
    rot = torch.polar(torch.ones_like(phi), -phi).to(b.dtype)
    return torch.einsum("bm,bmhw->bhw", rot, b).unsqueeze(1)


def pulse_autofocus(
    pulse_images: Tensor,
    *,
    p: float = 1.0,
    kappa: float = 1.5,
    max_iter: int = 200,
    tol: float = 1e-4,
    inner: int = 2,
) -> AutofocusResult:
    """Sparsity-driven 1-D autofocus from per-pulse images (matched-filter image step).

    Each item is processed scaled to unit peak amplitude (by a power of two, exactly; the
    weight and smoothing follow the data's scale), so data of any magnitude is focused
    without overflow: the result for ``s * b`` is the same phase and ``s`` times the image.

    Args:
        pulse_images: complex ``(B, M, H, W)``; complex128 is computed in double precision,
            every other complex dtype in complex64.
        p: L_p exponent in ``(0, 2]``.
        kappa: threshold in RMS pixel amplitudes of the uncorrected image (as
            :func:`default_lam`).
        max_iter: iteration limit.
        tol: relative image change that stops an item.
        inner: image updates per phase step.

    Returns:
        :class:`AutofocusResult` with ``image (B, 1, H, W)``, ``phase (B, M)``,
        ``iterations (B,)``; an all-zero item has nothing to focus and gets a zero image,
        phase 0 and 0 iterations.

    References:
        Önhon & Çetin 2012, doi:10.1109/TIP.2011.2174795; Ash, "An autofocus method for
        backprojection imagery in SAR", IEEE GRSL 9(1), 2012, doi:10.1109/LGRS.2011.2161456.

    Examples:
        >>> b = torch.zeros(1, 3, 4, 4, dtype=torch.complex64); b[0, :, 1, 1] = 1
        >>> b = b * torch.polar(torch.ones(3), torch.tensor([0.0, 1.0, 2.0]))[None, :, None, None]
        >>> float(pulse_autofocus(b).image.abs().max()) > 2.0
        True
    """
    b = as_complex(check_complex(pulse_images, "pulse_images", ndim=4))
    check_int(max_iter, "max_iter", minimum=0)
    check_int(inner, "inner", minimum=1)
    if check_positive(p, "p") > 2:
        raise OptionError(f"p must be in (0, 2], got {p}")
    check_positive(kappa, "kappa")
    check_positive(tol, "tol", allow_zero=True)
    live = nonzero_items(b)
    if not bool(live.all()):
        part = pulse_autofocus(b[live], p=p, kappa=kappa, max_iter=max_iter, tol=tol, inner=inner)
        return fill_result(live, part)
    scale = unit_scale(b).reshape(-1, 1, 1, 1)
    b = b / scale  # exact (a power of two); lam and eps follow the data's scale
    phi = torch.zeros(b.shape[:2], dtype=b.real.dtype, device=b.device)
    f = _form(b, phi)
    rms = f.flatten(1).norm(dim=1) / math.sqrt(max(1, f[0, 0].numel()))
    lam = (2 * (kappa * rms).pow(2 - p) / p)[:, None, None, None]
    eps = 1e-4 * (kappa * rms)[:, None, None, None].square()
    iters = torch.zeros(b.shape[0], dtype=torch.int64, device=b.device)
    active = torch.ones(b.shape[0], dtype=torch.bool, device=b.device)
    for it in range(1, max_iter + 1):
        if not bool(active.any()):
            break
        y, f_new = _form(b, phi), f
        for _ in range(inner):
            w = p * lam * (f_new.abs().square() + eps).pow(p / 2 - 1)
            f_new = 2 * y / (2 + w)
        phi_new = torch.einsum("bhw,bmhw->bm", f_new[:, 0].conj(), b).angle()
        change = (f_new - f).flatten(1).norm(dim=1) / f.flatten(1).norm(dim=1).clamp_min(1e-30)
        keep = active[:, None, None, None]
        f = torch.where(keep, f_new, f)
        phi = torch.where(active[:, None], phi_new, phi)
        iters = torch.where(active, it, iters)
        active = active & (change > tol)
    return AutofocusResult(image=f * scale, phase=phi, iterations=iters)


def pulse_min_entropy(pulse_images: Tensor, *, max_iter: int = 100) -> MinEntropyResult:
    """Minimum-entropy 1-D autofocus of ``sum_m exp(-1j phi_m) b_m`` (L-BFGS, autograd).

    The entropy does not depend on the data's scale; each item is processed scaled to unit
    peak amplitude (by a power of two, exactly), so data of any magnitude is focused without
    overflow.

    Args:
        pulse_images: complex ``(B, M, H, W)``; complex128 is computed in double precision,
            every other complex dtype in complex64.
        max_iter: L-BFGS iterations.

    Returns:
        :class:`MinEntropyResult` with ``image (B, 1, H, W)``, ``phase (B, M)``; an
        all-zero item gets a zero image, phase 0 and entropy 0.

    Examples:
        >>> b = torch.zeros(1, 3, 4, 4, dtype=torch.complex64); b[0, :, 1, 1] = 1
        >>> b = b * torch.polar(torch.ones(3), torch.tensor([0.0, 1.0, 2.0]))[None, :, None, None]
        >>> out = pulse_min_entropy(b)
        >>> out.image.shape, out.phase.shape
        (torch.Size([1, 1, 4, 4]), torch.Size([1, 3]))
    """
    b = as_complex(check_complex(pulse_images, "pulse_images", ndim=4).detach())
    check_int(max_iter, "max_iter", minimum=0)
    live = nonzero_items(b)
    if not bool(live.all()):
        return fill_result(live, pulse_min_entropy(b[live], max_iter=max_iter))
    scale = unit_scale(b)
    b = b / scale.reshape(-1, 1, 1, 1)  # exact (a power of two); the entropy is scale-free
    # One flat sum over the batch's pixels (this method's loss since it was written; the sum
    # order sets the rounding, and so the L-BFGS path).
    phi, iterations = lbfgs_phases(
        lambda phi: entropy_terms(_form(b, phi).abs().square().flatten(1)).sum(),
        b,
        max_iter=max_iter,
    )
    return entropy_result(_form(b, phi), phi, iterations, scale)
