"""Backprojection observation operator for deramped spotlight data on an arbitrary ground grid.

The exact model of pixel ``p`` in pulse ``m`` is ``exp(-1j U_k dR_mp)``, ``U_k = 4 pi f_k / c``,
``dR_mp = |a_m - p| - r0_m`` (differential range). With uniformly spaced frequencies
``f_k = f_0 + k df`` this factors into a carrier ``exp(-1j U_0 dR)`` and a DFT over ``k`` at the
continuous bin ``n = dR / dr``, ``dr = c / (2 N df)``. The operator evaluates that DFT on an
``upsample``-times zero-padded FFT grid with linear interpolation in range:

- adjoint ``C^H`` (backprojection): range-compress each pulse by a zero-padded inverse FFT,
  interpolate at every pixel's ``dR`` and multiply by ``exp(+1j U_0 dR)``; sum over pulses.
- forward ``C``: the exact transpose — scatter each pixel (times the conjugate carrier) onto
  the range bins with the same interpolation weights, FFT, keep the ``K`` samples.

So ``<C f, g> == <f, C^H g>`` holds to rounding, and ``C`` approximates the exact model (the
interpolation error shrinks with ``upsample``). Both are scaled by ``1 / sqrt(M K)``.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar._checks import check_int
from torchsar.errors import InputValueError, ShapeError
from torchsar.imaging._dtypes import as_complex
from torchsar.imaging.operators import LinearOperator
from torchsar.sar.geometry import SPEED_OF_LIGHT

__all__ = ["BackprojectionOperator"]


class BackprojectionOperator(LinearOperator):
    """Backprojection (adjoint) and its exact transpose (forward) for deramped phase histories.

    Args:
        freq: ``(K,)`` uniformly spaced frequencies in Hz.
        antenna: ``(M, 3)`` antenna phase-centre positions in metres.
        r0: ``(M,)`` range from the antenna to the scene centre (the deramp reference).
        x: ``(W,)`` pixel x coordinates (image columns) in metres.
        y: ``(H,)`` pixel y coordinates (image rows) in metres.
        z: height of the image plane in metres.
        upsample: range oversampling of the zero-padded FFT (interpolation accuracy).
        chunk: pulses processed at once (memory / speed trade-off).

    Raises:
        ShapeError: inconsistent geometry shapes.
        InputValueError: non-uniform frequency sampling.

    References:
        Gorham & Moore, "SAR image formation toolbox for MATLAB", Proc. SPIE 7699, 2010,
        doi:10.1117/12.855375.

    Examples:
        >>> freq = torch.linspace(9.5e9, 9.6e9, 16, dtype=torch.float64)
        >>> ant = torch.tensor([[1e4, 0.0, 5e3]], dtype=torch.float64).repeat(4, 1)
        >>> ant[:, 1] = torch.linspace(-50, 50, 4, dtype=torch.float64)
        >>> op = BackprojectionOperator(freq, ant, ant.norm(dim=1), torch.arange(-2.0, 2.0),
        ...                             torch.arange(-2.0, 2.0))
        >>> op.forward(torch.ones(1, 1, 4, 4, dtype=torch.complex64)).shape
        torch.Size([1, 4, 16])
    """

    def __init__(
        self,
        freq: Tensor,
        antenna: Tensor,
        r0: Tensor,
        x: Tensor,
        y: Tensor,
        *,
        z: float = 0.0,
        upsample: int = 8,
        chunk: int = 16,
    ) -> None:
        freq, antenna, r0 = (t.to(torch.float64) for t in (freq, antenna, r0))
        if antenna.dim() != 2 or antenna.shape[1] != 3 or r0.shape != antenna.shape[:1]:
            raise ShapeError(
                f"antenna must be (M, 3) and r0 (M,), got {tuple(antenna.shape)} and "
                f"{tuple(r0.shape)}"
            )
        df = freq.diff()
        if freq.numel() < 2 or not torch.allclose(df, df.mean(), rtol=1e-2, atol=0):
            raise InputValueError("freq must hold at least 2 uniformly spaced frequencies")
        self.freq, self.antenna, self.r0 = freq, antenna, r0
        self.data_shape = (antenna.shape[0], freq.numel())
        self.image_shape = (y.numel(), x.numel())
        yy, xx = torch.meshgrid(y.to(torch.float64), x.to(torch.float64), indexing="ij")
        self.pixels = torch.stack(
            [xx.reshape(-1), yy.reshape(-1), torch.full_like(xx, z).reshape(-1)], -1
        )
        self.nfft = 1 << math.ceil(
            math.log2(freq.numel() * check_int(upsample, "upsample", minimum=1))
        )
        self.bin = SPEED_OF_LIGHT / (2 * self.nfft * float(df.mean()))
        self.u0 = 4 * math.pi * float(freq[0]) / SPEED_OF_LIGHT
        self.chunk = check_int(chunk, "chunk", minimum=1)
        self.scale = 1 / math.sqrt(self.data_shape[0] * self.data_shape[1])

    def _geometry(self, sl: slice, device) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Bins ``i0``, ``i1``, weight of ``i1``, carrier ``exp(-1j U0 dR)`` for pulses ``sl``."""
        ant = self.antenna[sl].to(device)
        dr = (self.pixels.to(device)[None] - ant[:, None]).norm(dim=-1) - self.r0[sl].to(device)[
            :, None
        ]
        n = dr / self.bin
        i0 = n.floor()
        w1 = n - i0
        i0 = i0.long() % self.nfft
        carrier = torch.polar(torch.ones_like(dr), -self.u0 * dr)
        return i0, (i0 + 1) % self.nfft, w1, carrier

    def forward(self, f: Tensor) -> Tensor:
        """``C f``: image ``(B, 1, H, W)`` -> phase history ``(B, M, K)``."""
        f = as_complex(f).reshape(f.shape[0], self.pixels.shape[0])
        m, k = self.data_shape
        out = torch.zeros(f.shape[0], m, k, dtype=f.dtype, device=f.device)
        if f.shape[0] == 0:
            return out
        for s in range(0, m, self.chunk):
            sl = slice(s, min(m, s + self.chunk))
            i0, i1, w1, carrier = self._geometry(sl, f.device)
            v = f[:, None, :] * carrier.to(f.dtype)  # (B, m, P)
            t = torch.zeros(f.shape[0], i0.shape[0], self.nfft, dtype=f.dtype, device=f.device)
            t.scatter_add_(-1, i0.expand_as(v), v * (1 - w1).to(v.real.dtype))
            t.scatter_add_(-1, i1.expand_as(v), v * w1.to(v.real.dtype))
            out[:, sl] = torch.fft.fft(t, dim=-1)[..., :k]
        return out * self.scale

    def _backproject(self, g: Tensor, sl: slice) -> Tensor:
        """Per-pulse backprojections of pulses ``sl``: ``(B, m, P)`` (unscaled)."""
        i0, i1, w1, carrier = self._geometry(sl, g.device)
        prof = torch.fft.ifft(g[:, sl], n=self.nfft, dim=-1) * self.nfft  # (B, m, N)
        b = g.shape[0]
        v0 = torch.gather(prof, -1, i0.expand(b, *i0.shape))
        v1 = torch.gather(prof, -1, i1.expand(b, *i1.shape))
        w = w1.to(prof.real.dtype)
        return (v0 * (1 - w) + v1 * w) * carrier.conj().to(g.dtype)

    def adjoint(self, g: Tensor) -> Tensor:
        """``C^H g`` (backprojection): ``(B, M, K)`` -> image ``(B, 1, H, W)``."""
        g = as_complex(g)
        m, _ = self.data_shape
        img = torch.zeros(g.shape[0], self.pixels.shape[0], dtype=g.dtype, device=g.device)
        if g.shape[0] == 0:
            return img.reshape(0, 1, *self.image_shape)
        for s in range(0, m, self.chunk):
            img += self._backproject(g, slice(s, min(m, s + self.chunk))).sum(dim=1)
        return (img * self.scale).reshape(g.shape[0], 1, *self.image_shape)

    def pulse_images(self, g: Tensor) -> Tensor:
        """Per-pulse terms of the backprojection: ``(B, M, H, W)``, summing to ``C^H g``.

        ``C^H (exp(-1j phi) g) = sum_m exp(-1j phi_m) b_m`` for any per-pulse phase, which
        makes 1-D autofocus on backprojected imagery cheap (see :func:`pulse_autofocus`).
        """
        g = as_complex(g)
        m, _ = self.data_shape
        out = torch.zeros(g.shape[0], m, self.pixels.shape[0], dtype=g.dtype, device=g.device)
        if g.shape[0] > 0:
            for s in range(0, m, self.chunk):
                sl = slice(s, min(m, s + self.chunk))
                out[:, sl] = self._backproject(g, sl)
        return (out * self.scale).reshape(g.shape[0], m, *self.image_shape)
