"""Chirp-z transform (Bluestein): a DFT with an arbitrary frequency spacing per row."""

from __future__ import annotations

import math

import torch
from torch import Tensor

__all__ = ["czt"]


def czt(a: Tensor, alpha: Tensor, n_out: int) -> Tensor:
    """``y[..., n] = sum_m a[..., m] exp(1j * alpha[...] * m * n)`` for ``n < n_out``.

    Bluestein's identity ``m n = (m^2 + n^2 - (n - m)^2) / 2`` turns the sum into one
    convolution, computed with FFTs of length ``>= M + n_out - 1``: cost ``O(L log L)`` per
    row for any real ``alpha`` (one value per row). Chirp phases are formed in float64.

    Args:
        a: complex ``(..., M)``.
        alpha: real, broadcastable to ``a.shape[:-1]``: phase step per ``m * n``.
        n_out: number of outputs N.

    Returns:
        complex ``(..., N)`` in ``a``'s dtype.

    References:
        L. Bluestein, "A linear filtering approach to the computation of discrete Fourier
        transform", IEEE Trans. Audio Electroacoust. 18(4), 1970, doi:10.1109/TAU.1970.1162132.

    Examples:
        >>> a = torch.randn(3, 8, dtype=torch.complex128)
        >>> y = czt(a, torch.tensor(-2 * math.pi / 8, dtype=torch.float64), 8)
        >>> bool(torch.allclose(y, torch.fft.fft(a)))
        True
    """
    m_in = a.shape[-1]
    dev = a.device
    if a.numel() == 0:
        return torch.zeros(*a.shape[:-1], n_out, dtype=a.dtype, device=dev)
    length = 1 << math.ceil(math.log2(max(m_in + n_out - 1, 1)))
    al = torch.as_tensor(alpha, dtype=torch.float64, device=dev)
    al = al.expand(a.shape[:-1]).unsqueeze(-1)
    m = torch.arange(m_in, dtype=torch.float64, device=dev)
    n = torch.arange(n_out, dtype=torch.float64, device=dev)
    d = torch.arange(length, dtype=torch.float64, device=dev)
    d = torch.where(d < n_out, d, d - length)  # lags -(M-1)..(N-1), circularly placed
    cdt = a.dtype

    def chirp(x: Tensor, sign: float) -> Tensor:
        return torch.polar(
            torch.ones_like(x * al), torch.remainder(sign * al * x * x / 2, 2 * math.pi)
        ).to(cdt)

    b = torch.fft.fft(a * chirp(m, 1.0), n=length)
    h = torch.fft.fft(chirp(d, -1.0))
    return torch.fft.ifft(b * h)[..., :n_out] * chirp(n, 1.0)
