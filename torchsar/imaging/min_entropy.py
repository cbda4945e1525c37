"""Minimum-entropy autofocus: per-pulse phases minimising the entropy of the image intensity."""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from torchsar._checks import check_complex, check_int
from torchsar._scale import unit_scale
from torchsar.imaging._dtypes import as_complex
from torchsar.imaging.focus import intensity_entropy
from torchsar.imaging.fourier import ifft2c
from torchsar.imaging.items import nonzero_items
from torchsar.imaging.result import MinEntropyResult, fill_result

__all__ = ["entropy_result", "lbfgs_phases", "min_entropy_autofocus"]


def _rotate(g: Tensor, phi: Tensor) -> Tensor:
    """Image of the phase history corrected by the per-pulse phases ``phi``."""
    return ifft2c(g * torch.polar(torch.ones_like(phi), -phi)[..., None])


def _intensity(g: Tensor, phi: Tensor) -> Tensor:
    """Flattened intensity ``(B, M K)`` of the corrected image."""
    return _rotate(g, phi).abs().square().flatten(1)


def lbfgs_phases(
    loss: Callable[[Tensor], Tensor], like: Tensor, *, max_iter: int
) -> tuple[Tensor, Tensor]:
    """Per-pulse phases ``(B, M)`` minimising a scalar ``loss(phi)`` with L-BFGS from zero.

    The gradient comes from autograd. A loss that sums per-item terms decouples across the
    batch (items share only the line search, so the iteration count is shared too).

    Args:
        loss: phases ``(B, M)`` -> scalar tensor.
        like: a complex tensor ``(B, M, ...)`` giving the phases' shape, dtype and device.
        max_iter: L-BFGS iterations.

    Returns:
        ``(phases (B, M), iterations (B,) int64)``.

    Examples:
        >>> like = torch.zeros(2, 3, dtype=torch.complex64)
        >>> phi, it = lbfgs_phases(lambda p: (p - 1).square().sum(), like, max_iter=20)
        >>> torch.allclose(phi, torch.ones(2, 3)), it.tolist() == [it[0].item()] * 2
        (True, True)
    """
    phi = torch.zeros(like.shape[:2], dtype=like.real.dtype, device=like.device)
    phi.requires_grad_(True)
    iterations = 0
    if like.shape[0] > 0 and max_iter > 0:
        opt = torch.optim.LBFGS([phi], max_iter=max_iter, line_search_fn="strong_wolfe")

        def closure() -> Tensor:
            opt.zero_grad()
            value = loss(phi)
            value.backward()
            return value

        opt.step(closure)
        iterations = opt.state[phi].get("n_iter", 0)
    count = torch.full((like.shape[0],), iterations, dtype=torch.int64, device=like.device)
    return phi.detach(), count


def entropy_result(
    image: Tensor, phase: Tensor, iterations: Tensor, scale: Tensor | None = None
) -> MinEntropyResult:
    """:class:`MinEntropyResult` of a corrected complex ``image`` ``(B, 1, H, W)``, computed
    on data divided by ``scale`` (broadcastable per item; the image is scaled back, the
    entropy does not depend on it)."""
    entropy = intensity_entropy(image.abs().square().flatten(1))
    if scale is not None:
        image = image * scale.reshape(-1, 1, 1, 1).to(image.real.dtype)
    return MinEntropyResult(image=image, phase=phase, iterations=iterations, entropy=entropy)


def min_entropy_autofocus(g: Tensor, *, max_iter: int = 100) -> MinEntropyResult:
    """Estimate a 1-D (per-pulse) phase error by minimising image entropy with L-BFGS.

    The entropy of the image is a smooth function of the per-pulse phases; its gradient comes
    from autograd through :func:`ifft2c`. The sum of per-item entropies is minimised, which
    decouples across the batch (items share only the line search).

    The entropy does not depend on the data's scale, and each item is processed scaled to
    unit peak amplitude (by a power of two, exactly), so data of any magnitude is focused
    without overflow: the result for ``s * g`` is the same phase and ``s`` times the image.

    Args:
        g: complex phase history ``(B, M, K)``; complex128 is computed in double
            precision, every other complex dtype (complex64, complex32) in complex64.
        max_iter: L-BFGS iterations.

    Returns:
        :class:`MinEntropyResult` (image complex128 for complex128 data, else complex64).

    An all-zero item has nothing to focus: it is left out and gets phase 0, a zero image
    and entropy 0.

    Raises:
        InputTypeError, ShapeError: ``g`` is not a complex ``(B, M, K)`` tensor.

    References:
        Xi, Guosui & Ni, "Autofocusing of ISAR images based on entropy minimization",
        IEEE Trans. AES 35(4), 1999, doi:10.1109/7.805442.

    Examples:
        >>> from torchsar.imaging import fft2c, apply_phase_error
        >>> f = torch.zeros(1, 1, 16, 16, dtype=torch.complex64); f[0, 0, 3, 7] = 1
        >>> g = apply_phase_error(fft2c(f[:, 0]), 2 * torch.linspace(-1, 1, 16)[None] ** 2)
        >>> float(min_entropy_autofocus(g).image.abs().max()) > 0.95
        True
    """
    g = as_complex(check_complex(g, "g", ndim=3).detach())
    check_int(max_iter, "max_iter", minimum=0)
    live = nonzero_items(g)
    if not bool(live.all()):
        return fill_result(live, min_entropy_autofocus(g[live], max_iter=max_iter))
    scale = unit_scale(g).reshape(-1, 1, 1)
    g = g / scale  # exact (a power of two); the entropy does not depend on the scale
    phi, iterations = lbfgs_phases(
        lambda phi: intensity_entropy(_intensity(g, phi)).sum(), g, max_iter=max_iter
    )
    return entropy_result(_rotate(g, phi).unsqueeze(1), phi, iterations, scale)
