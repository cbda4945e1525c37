"""Exact-model simulation of deramped spotlight phase histories (no inverse crime).

The data are sums of ``a_n exp(-1j U_k (x_n cos th_m + y_n sin th_m))`` over scatterers,
evaluated on the polar raster of a :class:`~torchsar.imaging.SpotlightGeometry` — not with the
FFT operator that reconstructs them — optionally with the residual video phase (RVP) term
``exp(1j 4 alpha u^2 / c^2)`` of deramp-on-receive (``u`` = range offset of the scatterer).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar._checks import OptionError, ShapeError, check_complex
from torchsar.imaging._dtypes import complex_dtype
from torchsar.imaging.geometry import SPEED_OF_LIGHT, SpotlightGeometry

__all__ = ["add_noise", "phase_history", "point_phase_history"]

_CHUNK = 1 << 22  # complex elements per intermediate block


def phase_history(scene: Tensor, geometry: SpotlightGeometry, *, rvp: bool = False) -> Tensor:
    """Phase history of a reflectivity image with the exact polar-raster model.

    Pixel ``(i, j)`` sits at cross-range ``y_i`` and range ``x_j`` of
    :meth:`SpotlightGeometry.pixel_positions`. The result is scaled by ``1/sqrt(M K)`` so that
    on a narrow-angle geometry it approximates :class:`FourierOperator` (unitary) data.

    Args:
        scene: complex reflectivity ``(B, 1, H, W)``.
        geometry: acquisition geometry (``M`` pulses, ``K`` samples, pixel spacing).
        rvp: include the residual video phase (needs ``geometry.chirp_rate``).

    Returns:
        Complex phase history ``(B, M, K)`` (complex128 for float64-based input, else complex64).

    Raises:
        InputTypeError, ShapeError: ``scene`` is not a complex ``(B, 1, H, W)`` tensor.

    Shape:
        ``(B, 1, H, W) -> (B, M, K)``.

    References:
        Önhon & Çetin, SIU 2009, doi:10.1109/SIU.2009.5136449; Jakowatz et al. 1996,
        doi:10.1007/978-1-4613-1333-5 (deramp and RVP).

    Example:
        >>> geo = SpotlightGeometry.for_image((8, 8))
        >>> f = torch.zeros(1, 1, 8, 8, dtype=torch.complex64); f[0, 0, 4, 4] = 1
        >>> g = phase_history(f, geo)
        >>> torch.allclose(g.abs(), torch.full((1, 8, 8), 1 / 8.0))
        True
    """
    scene = check_complex(scene, "scene", ndim=4)
    if scene.shape[1] != 1:
        raise ShapeError(f"scene must have one channel (B, 1, H, W), got {tuple(scene.shape)}")
    if rvp:
        return _grid_as_points(scene, geometry)
    return _separable_sum(scene[:, 0], geometry)


def _phase_terms(geometry: SpotlightGeometry, device) -> tuple[Tensor, Tensor]:
    """``kx = U_k cos th_m`` and ``ky = U_k sin th_m``, each ``(M, K)`` float64."""
    u = geometry.wavenumbers(device=device)
    th = geometry.angles(device=device)
    return torch.outer(th.cos(), u), torch.outer(th.sin(), u)


def _separable_sum(f: Tensor, geometry: SpotlightGeometry) -> Tensor:
    """Exact sum using ``exp(-j(kx x + ky y)) = exp(-j kx x) exp(-j ky y)`` per sample."""
    b, h, w = f.shape
    m, k = geometry.pulses, geometry.samples
    kx, ky = _phase_terms(geometry, f.device)
    y, x = geometry.pixel_positions((h, w), device=f.device)
    out = torch.empty(b, m, k, dtype=f.dtype, device=f.device)
    step = max(1, _CHUNK // max(1, b * k * h))
    for m0 in range(0, m, step):
        sl = slice(m0, m0 + step)
        ex = torch.polar(torch.ones_like(kx[sl, :, None]), -kx[sl, :, None] * x).to(f.dtype)
        ey = torch.polar(torch.ones_like(ky[sl, :, None]), -ky[sl, :, None] * y).to(f.dtype)
        t = torch.einsum("bij,mkj->bmki", f, ex)
        out[:, sl] = torch.einsum("bmki,mki->bmk", t, ey)
    return out / (m * k) ** 0.5


def _grid_as_points(scene: Tensor, geometry: SpotlightGeometry) -> Tensor:
    b, _, h, w = scene.shape
    y, x = geometry.pixel_positions((h, w), device=scene.device)
    yy, xx = torch.meshgrid(y, x, indexing="ij")
    amps = scene.reshape(b, h * w)
    pos = torch.stack([xx.reshape(-1), yy.reshape(-1)], -1).expand(b, h * w, 2)
    g = point_phase_history(amps, pos, geometry, rvp=True)
    return g / (geometry.pulses * geometry.samples) ** 0.5


def point_phase_history(
    amplitudes: Tensor, positions: Tensor, geometry: SpotlightGeometry, *, rvp: bool = False
) -> Tensor:
    """Phase history of point scatterers at arbitrary (off-grid) positions (unscaled sum).

    Args:
        amplitudes: complex ``(B, N)`` scatterer reflectivities.
        positions: real ``(B, N, 2)`` positions ``(x = range, y = cross-range)`` in metres.
        geometry: acquisition geometry.
        rvp: multiply each term by the residual video phase ``exp(1j 4 alpha u^2 / c^2)``.

    Returns:
        Complex ``(B, M, K)``: ``sum_n a_n exp(-1j U_k u_nm) [* RVP]``,
        ``u_nm = x_n cos th_m + y_n sin th_m``.

    Example:
        >>> geo = SpotlightGeometry.for_image((4, 4))
        >>> a = torch.ones(1, 1, dtype=torch.complex128)
        >>> point_phase_history(a, torch.zeros(1, 1, 2), geo).abs().max().item()
        1.0
    """
    amplitudes = check_complex(amplitudes, "amplitudes", ndim=2)
    b, n = amplitudes.shape
    if positions.shape != (b, n, 2):
        raise ShapeError(
            f"positions must have shape (B, N, 2) = {(b, n, 2)}, got {tuple(positions.shape)}"
        )
    dev = amplitudes.device
    u_k = geometry.wavenumbers(device=dev)
    th = geometry.angles(device=dev)
    pos = positions.to(device=dev, dtype=torch.float64)
    out = torch.zeros(b, geometry.pulses, geometry.samples, dtype=torch.complex128, device=dev)
    step = max(1, _CHUNK // max(1, b * geometry.pulses * geometry.samples))
    for n0 in range(0, n, step):
        p = pos[:, n0 : n0 + step]
        u = p[..., :1] * th.cos() + p[..., 1:] * th.sin()  # (B, n, M)
        phase = -u[..., None] * u_k
        if rvp:
            rvp_rate = 4 * math.pi * geometry.chirp_rate / SPEED_OF_LIGHT**2  # gamma in Hz/s
            phase = phase + rvp_rate * u[..., None] ** 2
        terms = torch.polar(torch.ones_like(phase), phase)
        out += torch.einsum("bn,bnmk->bmk", amplitudes[:, n0 : n0 + step].to(out.dtype), terms)
    return out.to(complex_dtype(amplitudes.dtype))


def add_noise(g: Tensor, *, snr_db: float, generator: torch.Generator | None = None) -> Tensor:
    """Add circular complex white Gaussian noise at a per-item SNR (dB) over ``(M, K)``.

    Args:
        g: complex phase history ``(B, M, K)``.
        snr_db: signal-to-noise ratio ``10 log10(mean|g|^2 / sigma^2)`` of every item.
        generator: torch random generator for reproducibility.

    Returns:
        Noisy phase history, same shape and dtype.

    Example:
        >>> g = torch.ones(2, 8, 8, dtype=torch.complex64)
        >>> add_noise(g, snr_db=20.0, generator=torch.Generator().manual_seed(0)).shape
        torch.Size([2, 8, 8])
    """
    g = check_complex(g, "g", ndim=3)
    if isinstance(snr_db, bool) or not isinstance(snr_db, int | float):
        raise OptionError(f"snr_db must be a real number, got {snr_db!r}")
    power = g.abs().square().mean(dim=(-2, -1), keepdim=True)
    sigma = (power / 10 ** (float(snr_db) / 10) / 2).sqrt()
    real = torch.randn(g.shape, generator=generator, dtype=sigma.dtype, device=g.device)
    imag = torch.randn(g.shape, generator=generator, dtype=sigma.dtype, device=g.device)
    return g + sigma * torch.complex(real, imag)
