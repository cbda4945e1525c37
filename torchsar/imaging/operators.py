"""Linear SAR observation operators ``C``: image ``(B, 1, H, W)`` -> phase history ``(B, M, K)``.

Every operator offers ``forward`` (``C f``), ``adjoint`` (``C^H g``) and ``normal``
(``C^H C f``), and says whether ``C^H C`` is the identity (``gram_is_identity``) so the
image step of :func:`torchsar.imaging.lp_image` can use the diagonal closed form instead of
conjugate gradient. Every operator passes the adjoint test ``<C f, g> == <f, C^H g>``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import torch
from torch import Tensor

from torchsar._checks import check_complex
from torchsar.errors import InputTypeError, ShapeError
from torchsar.imaging._dtypes import as_complex
from torchsar.imaging.fourier import fft2c, ifft2c

__all__ = ["FourierOperator", "LinearOperator"]


class LinearOperator(ABC):
    """Base class of observation operators (image ``(B,1,H,W)`` <-> data ``(B,M,K)``).

    Subclasses set ``image_shape`` ``(H, W)``, ``data_shape`` ``(M, K)`` and
    ``gram_is_identity`` and implement :meth:`forward` and :meth:`adjoint`.
    """

    image_shape: tuple[int, int]
    data_shape: tuple[int, int]
    gram_is_identity: bool = False

    @abstractmethod
    def forward(self, f: Tensor) -> Tensor:
        """Return ``C f``: image ``(B, 1, H, W)`` -> phase history ``(B, M, K)``."""

    @abstractmethod
    def adjoint(self, g: Tensor) -> Tensor:
        """Return ``C^H g``: phase history ``(B, M, K)`` -> image ``(B, 1, H, W)``."""

    def normal(self, f: Tensor) -> Tensor:
        """Return ``C^H C f``."""
        return self.adjoint(self.forward(f))

    def select(self, index: Tensor) -> LinearOperator:
        """The operator for the batch items ``index`` (itself unless it is per-item)."""
        return self

    def __call__(self, f: Tensor) -> Tensor:
        return self.forward(f)

    def check_data(self, g: object, name: str = "g") -> Tensor:
        """Validate a phase history for this operator and return it as complex."""
        g = check_complex(g, name, ndim=3)
        if tuple(g.shape[-2:]) != tuple(self.data_shape):
            raise ShapeError(
                f"{name} must have shape (B, M, K) = (B, {self.data_shape[0]}, "
                f"{self.data_shape[1]}) for this operator, got {tuple(g.shape)}"
            )
        return as_complex(g)


class FourierOperator(LinearOperator):
    """Unitary centred 2-D DFT observation model, optionally with missing samples.

    ``C f = mask * fft2c(f)``. Without a mask ``C^H C = I``; with a sampling mask (missing
    pulses or frequencies) ``C^H C = F^H D F`` is not the identity and imaging uses
    conjugate gradient.

    Args:
        shape: ``(M, K)`` = ``(H, W)``: pulses (image rows, cross-range) and frequency
            samples (image columns, range).
        mask: optional bool tensor broadcastable to ``(B, M, K)``; ``True`` = sample observed.

    Raises:
        ShapeError: mask does not broadcast to ``shape``.

    Examples:
        >>> op = FourierOperator((8, 8))
        >>> f = torch.randn(2, 1, 8, 8, dtype=torch.complex64)
        >>> torch.allclose(op.adjoint(op.forward(f)), f, atol=1e-6)
        True
    """

    def __init__(self, shape: tuple[int, int], *, mask: Tensor | None = None) -> None:
        m, k = (int(s) for s in shape)
        self.image_shape = (m, k)
        self.data_shape = (m, k)
        self.mask = None if mask is None else _check_sampling_mask(mask, (m, k))
        self.gram_is_identity = mask is None

    def select(self, index: Tensor) -> FourierOperator:
        """The operator for batch items ``index`` (slices a per-item ``(B, M, K)`` mask)."""
        if self.mask is None or self.mask.dim() == 2:
            return self
        return FourierOperator(self.image_shape, mask=self.mask[index.to(self.mask.device)])

    def forward(self, f: Tensor) -> Tensor:
        """``C f``: ``(B, 1, M, K)`` image -> ``(B, M, K)`` phase history."""
        g = fft2c(as_complex(f)).squeeze(-3)
        return g if self.mask is None else g * self.mask.to(g.device)

    def adjoint(self, g: Tensor) -> Tensor:
        """``C^H g``: ``(B, M, K)`` phase history -> ``(B, 1, M, K)`` image."""
        g = as_complex(g)
        if self.mask is not None:
            g = g * self.mask.to(g.device)
        return ifft2c(g).unsqueeze(-3)


def _check_sampling_mask(mask: object, shape: tuple[int, int]) -> Tensor:
    """Validate a bool sampling mask broadcastable to ``(B, M, K)``."""
    if not isinstance(mask, Tensor):
        raise InputTypeError(f"mask must be a torch.Tensor, got {type(mask).__name__}")
    if mask.dtype != torch.bool:
        raise InputTypeError(f"mask must be a bool tensor, got dtype {mask.dtype}")
    if mask.dim() < 2 or mask.dim() > 3 or tuple(mask.shape[-2:]) != shape:
        raise ShapeError(
            f"mask must have shape (M, K) or (B, M, K) with (M, K) = {shape}, "
            f"got {tuple(mask.shape)}"
        )
    return mask
