"""Phase-error generators (1-D per pulse and 2-D) and their application to phase histories.

Convention: corrupted data ``g = exp(1j phi) * (C f)``; a 1-D error is ``(B, M)``,
a 2-D error ``(B, M, K)``. Every generator takes ``(batch, pulses[, samples])``, then its own
keyword options, then the shared ``amplitude``, ``seed``, ``dtype`` and ``device``. Generators
draw one independent error per batch item: item ``i``
draws only from the generator seeded with :func:`~torchsar.seeding.image_seed`
``(seed, i)``, so an item's error does not depend on the batch size (``seed`` in
``[0, 2**63)``; the same seed gives the same errors).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
from torch import Tensor

from torchsar._checks import all_finite, check_complex, check_int, check_positive
from torchsar.errors import InputValueError, OptionError, ShapeError
from torchsar.seeding import check_seed, image_seed, make_generator

__all__ = [
    "apply_phase_error",
    "polynomial_phase_error",
    "quadratic_phase_error",
    "sinusoidal_phase_error",
    "uniform_phase_error",
]

Draw = Callable[[torch.Generator], Tensor]


def _per_item(batch: int, pulses: int, amplitude: float, seed: int, draw: Draw, device) -> Tensor:
    """Validate the shared options and stack one ``draw`` per item, each from its own generator.

    ``draw(generator)`` returns one item's error (``(M,)`` or ``(M, K)``, on the CPU).
    """
    check_int(batch, "batch", minimum=0)
    check_int(pulses, "pulses", minimum=1)
    check_positive(amplitude, "amplitude")
    seed = check_seed(seed)
    # An empty batch still draws one item, only for its shape and dtype.
    items = [draw(make_generator(image_seed(seed, i))) for i in range(max(batch, 1))]
    return torch.stack(items)[:batch].to(device)


def _uniform(shape: tuple[int, ...], amplitude: float, generator: torch.Generator, dtype) -> Tensor:
    """Uniform in ``[-amplitude, amplitude]``."""
    return (2 * torch.rand(shape, generator=generator, dtype=dtype) - 1) * amplitude


def _axis(n: int, dtype) -> Tensor:
    """Normalised slow-time axis in ``[-1, 1]`` (``(n,)``)."""
    return torch.linspace(-1.0, 1.0, n, dtype=dtype) if n > 1 else torch.zeros(1, dtype=dtype)


def uniform_phase_error(
    batch: int,
    pulses: int,
    samples: int | None = None,
    *,
    separable: bool = False,
    amplitude: float = math.pi,
    seed: int = 0,
    dtype: torch.dtype = torch.float32,
    device=None,
) -> Tensor:
    """Independent phase errors uniform in ``[-amplitude, amplitude]``, of the three structures
    :func:`sparse_autofocus` corrects.

    Args:
        batch: number of errors ``B``.
        pulses: pulses ``M``.
        samples: range samples ``K`` for a 2-D error (default: a 1-D per-pulse error).
        separable: with ``samples``, a separable error ``phi_m + psi_k`` (both terms uniform)
            instead of an independent value per sample.
        amplitude: bound of each uniform term.
        seed: seed in ``[0, 2**63)`` (item ``i`` from ``image_seed(seed, i)``).
        dtype: real dtype of the result.
        device: device of the result.

    Returns:
        ``(B, M)`` (1-D, ``"1d"``), or ``(B, M, K)`` (``"2d-separable"`` with ``separable``,
        else ``"2d"``).

    Raises:
        OptionError: invalid sizes, ``amplitude`` or ``seed``, or ``separable`` without
            ``samples``.

    Examples:
        >>> uniform_phase_error(2, 8, seed=0).shape
        torch.Size([2, 8])
        >>> phi = uniform_phase_error(1, 4, 6, separable=True, amplitude=1.0)
        >>> bool((phi - phi[:, :1] - phi[:, :, :1] + phi[:, :1, :1]).abs().max() < 1e-6)
        True
    """
    if samples is not None:
        check_int(samples, "samples", minimum=1)
    elif separable:
        raise OptionError("separable needs samples (a 2-D error), got samples=None")

    def draw(gen: torch.Generator) -> Tensor:
        if samples is None:
            return _uniform((pulses,), amplitude, gen, dtype)
        if separable:
            rows = _uniform((pulses, 1), amplitude, gen, dtype)
            return rows + _uniform((1, samples), amplitude, gen, dtype)
        return _uniform((pulses, samples), amplitude, gen, dtype)

    return _per_item(batch, pulses, amplitude, seed, draw, device)


def quadratic_phase_error(
    batch: int,
    pulses: int,
    *,
    amplitude: float = math.pi,
    seed: int = 0,
    dtype: torch.dtype = torch.float32,
    device=None,
) -> Tensor:
    """Quadratic ``c t^2``, t in [-1, 1], ``|c|`` uniform in ``[amplitude/2, amplitude]``.

    Examples:
        >>> phi = quadratic_phase_error(1, 5, amplitude=2.0, seed=0)
        >>> bool(phi[0, 2] == 0)
        True
    """

    def draw(gen: torch.Generator) -> Tensor:
        mag = amplitude * (0.5 + 0.5 * torch.rand(1, generator=gen, dtype=dtype))
        sign = torch.where(torch.rand(1, generator=gen, dtype=dtype) < 0.5, -1.0, 1.0)
        return sign * mag * _axis(pulses, dtype).square()

    return _per_item(batch, pulses, amplitude, seed, draw, device)


def polynomial_phase_error(
    batch: int,
    pulses: int,
    *,
    order: int = 4,
    amplitude: float = math.pi,
    seed: int = 0,
    dtype: torch.dtype = torch.float32,
    device=None,
) -> Tensor:
    """Random polynomials of degrees 2..``order`` (Legendre basis), peak ``|phi|`` = ``amplitude``.

    Examples:
        >>> phi = polynomial_phase_error(3, 16, amplitude=1.0, seed=0)
        >>> torch.allclose(phi.abs().amax(dim=1), torch.ones(3))
        True
    """
    check_int(order, "order", minimum=2)

    def draw(gen: torch.Generator) -> Tensor:
        t = _axis(pulses, torch.float64)
        basis = torch.stack([_legendre(n, t) for n in range(2, order + 1)])  # (order-1, M)
        phi = torch.randn(order - 1, generator=gen, dtype=torch.float64) @ basis
        return (phi / phi.abs().amax().clamp_min(1e-12) * amplitude).to(dtype)

    return _per_item(batch, pulses, amplitude, seed, draw, device)


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
    cycles: tuple[float, float] = (0.5, 3.0),
    amplitude: float = math.pi,
    seed: int = 0,
    dtype: torch.dtype = torch.float32,
    device=None,
) -> Tensor:
    """``amplitude * sin(2 pi c t + psi)`` with ``c`` uniform in ``cycles`` over the aperture.

    Examples:
        >>> sinusoidal_phase_error(2, 32, amplitude=1.0).abs().max() <= 1.0
        tensor(True)
    """

    def draw(gen: torch.Generator) -> Tensor:
        c = cycles[0] + (cycles[1] - cycles[0]) * torch.rand(1, generator=gen, dtype=dtype)
        psi = 2 * math.pi * torch.rand(1, generator=gen, dtype=dtype)
        t = (_axis(pulses, dtype) + 1) / 2
        return amplitude * torch.sin(2 * math.pi * c * t + psi)

    return _per_item(batch, pulses, amplitude, seed, draw, device)


def apply_phase_error(g: Tensor, phi: Tensor) -> Tensor:
    """Return ``exp(1j phi) * g`` for a 1-D ``(B, M)`` or 2-D ``(B, M, K)`` error.

    Correct data with ``apply_phase_error(g, -phi_hat)``.

    Raises:
        ShapeError: ``phi`` matches neither ``(B, M)`` nor ``(B, M, K)``.
        InputValueError: ``phi`` holds NaN or Inf.

    Examples:
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
    if not all_finite(phi):
        raise InputValueError("phi must be finite, got NaN or Inf phases")
    if tuple(phi.shape) == tuple(shape[:2]):
        return phi.unsqueeze(-1)
    if tuple(phi.shape) == tuple(shape):
        return phi
    raise ShapeError(
        f"phi must have shape (B, M) = {tuple(shape[:2])} or (B, M, K) = {tuple(shape)}, "
        f"got {tuple(phi.shape)}"
    )
