"""Minimum-entropy autofocus: per-pulse phases minimising the entropy of the image intensity."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar._checks import check_complex, check_int
from torchsar.imaging.focus import intensity_entropy
from torchsar.imaging.fourier import ifft2c
from torchsar.imaging.items import fill_items, nonzero_items

__all__ = ["MinEntropyResult", "min_entropy_autofocus"]


@dataclass(frozen=True)
class MinEntropyResult:
    """Output of :func:`min_entropy_autofocus`: ``image`` ``(B, 1, M, K)``, ``phase`` ``(B, M)``,
    final ``entropy`` ``(B,)``."""

    image: Tensor
    phase: Tensor
    entropy: Tensor


def _entropy(g: Tensor, phi: Tensor) -> Tensor:
    """Entropy of ``|ifft2c(exp(-1j phi) g)|^2`` per item."""
    img = ifft2c(g * torch.polar(torch.ones_like(phi), -phi)[..., None])
    return intensity_entropy(img.abs().square().flatten(1))


def min_entropy_autofocus(g: Tensor, *, max_iter: int = 100) -> MinEntropyResult:
    """Estimate a 1-D (per-pulse) phase error by minimising image entropy with L-BFGS.

    The entropy of the image is a smooth function of the per-pulse phases; its gradient comes
    from autograd through :func:`ifft2c`. The sum of per-item entropies is minimised, which
    decouples across the batch (items share only the line search).

    Args:
        g: complex phase history ``(B, M, K)``.
        max_iter: L-BFGS iterations.

    Returns:
        :class:`MinEntropyResult`.

    An all-zero item has nothing to focus: it is left out and gets phase 0, a zero image
    and entropy 0.

    Raises:
        InputTypeError, ShapeError: ``g`` is not a complex ``(B, M, K)`` tensor.

    References:
        Xi, Guosui & Ni, "Autofocusing of ISAR images based on entropy minimization",
        IEEE Trans. AES 35(4), 1999, doi:10.1109/7.805442.

    Example:
        >>> from torchsar.imaging import fft2c, apply_phase_error
        >>> f = torch.zeros(1, 1, 16, 16, dtype=torch.complex64); f[0, 0, 3, 7] = 1
        >>> g = apply_phase_error(fft2c(f[:, 0]), 2 * torch.linspace(-1, 1, 16)[None] ** 2)
        >>> float(min_entropy_autofocus(g).image.abs().max()) > 0.95
        True
    """
    g = check_complex(g, "g", ndim=3)
    check_int(max_iter, "max_iter", minimum=0)
    g = g.detach()
    live = nonzero_items(g)
    if not bool(live.all()):
        part = min_entropy_autofocus(g[live], max_iter=max_iter)
        return MinEntropyResult(
            *(fill_items(live, x) for x in (part.image, part.phase, part.entropy))
        )
    phi = torch.zeros(g.shape[:2], dtype=g.real.dtype, device=g.device, requires_grad=True)
    if g.shape[0] > 0 and max_iter > 0:
        opt = torch.optim.LBFGS([phi], max_iter=max_iter, line_search_fn="strong_wolfe")

        def closure() -> Tensor:
            opt.zero_grad()
            loss = _entropy(g, phi).sum()
            loss.backward()
            return loss

        opt.step(closure)
    phi = phi.detach()
    img = ifft2c(g * torch.polar(torch.ones_like(phi), -phi)[..., None]).unsqueeze(1)
    return MinEntropyResult(img, phi, _entropy(g, phi))
