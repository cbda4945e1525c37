"""Phase-error generators (1-D per pulse and 2-D) and their application to phase histories.

Convention: corrupted data ``g = exp(1j phi) * (C f)``; a 1-D error is ``(B, M)``,
a 2-D error ``(B, M, K)``. Generators draw one independent error per batch item.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar._checks import ShapeError, check_complex, check_int, check_positive

__all__ = [
    "apply_phase_error",
    "nonseparable_phase_error",
    "polynomial_phase_error",
    "quadratic_phase_error",
    "separable_phase_error",
    "sinusoidal_phase_error",
    "uniform_phase_error",
]

Gen = torch.Generator | None


def _uniform(shape: tuple[int, ...], amplitude: float, generator: Gen, dtype, device) -> Tensor:
    """Uniform in ``[-amplitude, amplitude]``."""
    u = torch.rand(shape, generator=generator, dtype=dtype)
    return ((2 * u - 1) * amplitude).to(device)


def _axis(n: int, dtype) -> Tensor:
    """Normalised slow-time axis in ``[-1, 1]`` (``(n,)``)."""
    return torch.linspace(-1.0, 1.0, n, dtype=dtype) if n > 1 else torch.zeros(1, dtype=dtype)


def _check(batch: int, pulses: int, amplitude: float) -> None:
    check_int(batch, "batch", minimum=0)
    check_int(pulses, "pulses", minimum=1)
    check_positive(amplitude, "amplitude")


def uniform_phase_error(
    batch: int,
    pulses: int,
    *,
    amplitude: float = math.pi,
    generator: Gen = None,
    dtype: torch.dtype = torch.float32,
    device=None,
) -> Tensor:
    """Independent per-pulse phase errors uniform in ``[-amplitude, amplitude]``, ``(B, M)``.

    Example:
        >>> uniform_phase_error(2, 8, generator=torch.Generator().manual_seed(0)).shape
        torch.Size([2, 8])
    """
    _check(batch, pulses, amplitude)
    return _uniform((batch, pulses), amplitude, generator, dtype, device)


def quadratic_phase_error(
    batch: int,
    pulses: int,
    *,
    amplitude: float = math.pi,
    generator: Gen = None,
    dtype: torch.dtype = torch.float32,
    device=None,
) -> Tensor:
    """Quadratic ``c t^2``, t in [-1, 1], ``|c|`` uniform in ``[amplitude/2, amplitude]``.

    Example:
        >>> gen = torch.Generator().manual_seed(0)
        >>> phi = quadratic_phase_error(1, 5, amplitude=2.0, generator=gen)
        >>> bool(phi[0, 2] == 0)
        True
    """
    _check(batch, pulses, amplitude)
    mag = amplitude * (0.5 + 0.5 * torch.rand(batch, 1, generator=generator, dtype=dtype))
    sign = torch.where(torch.rand(batch, 1, generator=generator, dtype=dtype) < 0.5, -1.0, 1.0)
    return (sign * mag * _axis(pulses, dtype).square()).to(device)


def polynomial_phase_error(
    batch: int,
    pulses: int,
    *,
    order: int = 4,
    amplitude: float = math.pi,
    generator: Gen = None,
    dtype: torch.dtype = torch.float32,
    device=None,
) -> Tensor:
    """Random polynomials of degrees 2..``order`` (Legendre basis), peak ``|phi|`` = ``amplitude``.

    Example:
        >>> gen = torch.Generator().manual_seed(0)
        >>> phi = polynomial_phase_error(3, 16, amplitude=1.0, generator=gen)
        >>> torch.allclose(phi.abs().amax(dim=1), torch.ones(3))
        True
    """
    _check(batch, pulses, amplitude)
    check_int(order, "order", minimum=2)
    t = _axis(pulses, torch.float64)
    basis = torch.stack([_legendre(n, t) for n in range(2, order + 1)])  # (order-1, M)
    coef = torch.randn(batch, order - 1, generator=generator, dtype=torch.float64)
    phi = coef @ basis
    phi = phi / phi.abs().amax(dim=1, keepdim=True).clamp_min(1e-12) * amplitude
    return phi.to(dtype=dtype, device=device)


def _legendre(n: int, t: Tensor) -> Tensor:
    """Legendre polynomial ``P_n(t)`` by the three-term recurrence."""
    p0, p1 = torch.ones_like(t), t
    for k in range(1, n):
        p0, p1 = p1, ((2 * k + 1) * t * p1 - k * p0) / (k + 1)
    return p1 if n >= 1 else p0


def sinusoidal_phase_error(
    batch: int,
    pulses: int,
    *,
    amplitude: float = math.pi,
    cycles: tuple[float, float] = (0.5, 3.0),
    generator: Gen = None,
    dtype: torch.dtype = torch.float32,
    device=None,
) -> Tensor:
    """``amplitude * sin(2 pi c t + psi)`` with ``c`` uniform in ``cycles`` over the aperture.

    Example:
        >>> sinusoidal_phase_error(2, 32, amplitude=1.0).abs().max() <= 1.0
        tensor(True)
    """
    _check(batch, pulses, amplitude)
    c = cycles[0] + (cycles[1] - cycles[0]) * torch.rand(batch, 1, generator=generator, dtype=dtype)
    psi = 2 * math.pi * torch.rand(batch, 1, generator=generator, dtype=dtype)
    t = (_axis(pulses, dtype) + 1) / 2
    return (amplitude * torch.sin(2 * math.pi * c * t + psi)).to(device)


def separable_phase_error(
    batch: int,
    pulses: int,
    samples: int,
    *,
    amplitude: float = 0.75 * math.pi,
    generator: Gen = None,
    dtype: torch.dtype = torch.float32,
    device=None,
) -> Tensor:
    """2-D separable error ``phi_m + psi_k``, both uniform in ``[-amplitude, amplitude]``.

    Example:
        >>> separable_phase_error(1, 4, 6).shape
        torch.Size([1, 4, 6])
    """
    _check(batch, pulses, amplitude)
    check_int(samples, "samples", minimum=1)
    rows = _uniform((batch, pulses, 1), amplitude, generator, dtype, device)
    cols = _uniform((batch, 1, samples), amplitude, generator, dtype, device)
    return rows + cols


def nonseparable_phase_error(
    batch: int,
    pulses: int,
    samples: int,
    *,
    amplitude: float = 0.75 * math.pi,
    generator: Gen = None,
    dtype: torch.dtype = torch.float32,
    device=None,
) -> Tensor:
    """2-D non-separable error: independent per sample, uniform in ``[-amplitude, amplitude]``.

    Example:
        >>> nonseparable_phase_error(2, 4, 6).shape
        torch.Size([2, 4, 6])
    """
    _check(batch, pulses, amplitude)
    check_int(samples, "samples", minimum=1)
    return _uniform((batch, pulses, samples), amplitude, generator, dtype, device)


def apply_phase_error(g: Tensor, phi: Tensor) -> Tensor:
    """Return ``exp(1j phi) * g`` for a 1-D ``(B, M)`` or 2-D ``(B, M, K)`` error.

    Correct data with ``apply_phase_error(g, -phi_hat)``.

    Raises:
        ShapeError: ``phi`` matches neither ``(B, M)`` nor ``(B, M, K)``.

    Example:
        >>> g = torch.ones(1, 2, 3, dtype=torch.complex64)
        >>> apply_phase_error(g, torch.zeros(1, 2)).equal(g)
        True
    """
    g = check_complex(g, "g", ndim=3)
    phi = _expand_phase(phi, g.shape)
    return g * torch.polar(torch.ones_like(phi), phi).to(g.dtype)


def _expand_phase(phi: Tensor, shape: torch.Size) -> Tensor:
    """Broadcast a ``(B, M)`` or ``(B, M, K)`` phase to ``(B, M, K)``-compatible shape."""
    if not isinstance(phi, Tensor) or phi.is_complex():
        raise ShapeError(f"phi must be a real tensor, got {type(phi).__name__}")
    if tuple(phi.shape) == tuple(shape[:2]):
        return phi.unsqueeze(-1)
    if tuple(phi.shape) == tuple(shape):
        return phi
    raise ShapeError(
        f"phi must have shape (B, M) = {tuple(shape[:2])} or (B, M, K) = {tuple(shape)}, "
        f"got {tuple(phi.shape)}"
    )
