"""Centred, orthonormal 2-D Fourier transforms between images and phase histories.

``fft2c`` maps an image (rows = cross-range, columns = range) to a phase history
(rows = pulses, columns = frequency samples) with the zero frequency and the image centre
both at index ``N // 2``; ``ifft2c`` is its inverse and adjoint. Both act on the last two
dimensions of a tensor of any leading shape and are unitary (``norm="ortho"``), so
``C^H C = I`` for the full-aperture Fourier operator.
"""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar.errors import InputTypeError, ShapeError
from torchsar.imaging._dtypes import complex_dtype

__all__ = ["fft2c", "ifft2c"]

_DIMS = (-2, -1)


def _check_2d(x: object, name: str) -> Tensor:
    if not isinstance(x, Tensor):
        raise InputTypeError(f"{name} must be a torch.Tensor, got {type(x).__name__}")
    if x.dim() < 2:
        raise ShapeError(f"{name} must have at least 2 dims (..., H, W), got {tuple(x.shape)}")
    if not (x.is_complex() or x.is_floating_point()):
        raise InputTypeError(f"{name} must be floating or complex, got dtype {x.dtype}")
    return x


def _empty_complex(x: Tensor) -> Tensor:
    """An empty complex tensor like ``x`` (torch.fft rejects zero-size inputs)."""
    return torch.zeros(x.shape, dtype=complex_dtype(x.dtype), device=x.device)


def fft2c(x: Tensor) -> Tensor:
    """Centred orthonormal 2-D FFT over the last two dimensions (image -> phase history).

    Args:
        x: real or complex tensor ``(..., H, W)``.

    Returns:
        Complex tensor of the same shape: ``fftshift(fft2(ifftshift(x), norm="ortho"))``.

    Raises:
        InputTypeError: not a floating/complex tensor.
        ShapeError: fewer than 2 dimensions.

    Shape:
        ``(..., H, W) -> (..., H, W)``.

    References:
        Jakowatz et al., *Spotlight-Mode Synthetic Aperture Radar*, Kluwer 1996,
        doi:10.1007/978-1-4613-1333-5.

    Examples:
        >>> x = torch.zeros(1, 4, 4, dtype=torch.complex64); x[0, 2, 2] = 1
        >>> torch.allclose(fft2c(x).abs(), torch.full((1, 4, 4), 0.25))
        True
    """
    x = _check_2d(x, "x")
    if x.numel() == 0:
        return _empty_complex(x)
    return torch.fft.fftshift(torch.fft.fft2(torch.fft.ifftshift(x, _DIMS), norm="ortho"), _DIMS)


def ifft2c(g: Tensor) -> Tensor:
    """Centred orthonormal inverse 2-D FFT (phase history -> image); adjoint of :func:`fft2c`.

    Args:
        g: real or complex tensor ``(..., M, K)``.

    Returns:
        Complex tensor of the same shape.

    Raises:
        InputTypeError: not a floating/complex tensor.
        ShapeError: fewer than 2 dimensions.

    Shape:
        ``(..., M, K) -> (..., M, K)``.

    Examples:
        >>> x = torch.randn(2, 8, 8, dtype=torch.complex128)
        >>> torch.allclose(ifft2c(fft2c(x)), x)
        True
    """
    g = _check_2d(g, "g")
    if g.numel() == 0:
        return _empty_complex(g)
    return torch.fft.fftshift(torch.fft.ifft2(torch.fft.ifftshift(g, _DIMS), norm="ortho"), _DIMS)
