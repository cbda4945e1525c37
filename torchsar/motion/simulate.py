"""Deramped spotlight phase history of point targets, stationary or moving."""

from __future__ import annotations

import torch
from torch import Tensor

from torchsar._checks import InputTypeError, ShapeError, check_int, check_positive
from torchsar.motion.geometry import pulse_times, slant_ranges, wavenumbers
from torchsar.motion.params import SpotlightParams

__all__ = ["simulate_phase_history"]


def _check_points(positions: object, velocities: object, amplitudes: object) -> None:
    """Validate ``(B, N, 2)`` positions, matching velocities and ``(B, N)`` amplitudes."""
    if not isinstance(positions, Tensor) or not positions.is_floating_point():
        raise InputTypeError(f"positions must be a real floating tensor, got {positions!r:.60}")
    if positions.dim() != 3 or positions.shape[-1] != 2:
        raise ShapeError(
            f"positions must have shape (B, N, 2) as (range, azimuth) metres, "
            f"got {tuple(positions.shape)}"
        )
    for name, x, shape in (
        ("velocities", velocities, positions.shape),
        ("amplitudes", amplitudes, positions.shape[:2]),
    ):
        if x is not None and (not isinstance(x, Tensor) or x.shape != shape):
            got = tuple(x.shape) if isinstance(x, Tensor) else type(x).__name__
            raise ShapeError(f"{name} must have shape {tuple(shape)}, got {got}")


def simulate_phase_history(
    positions: Tensor,
    params: SpotlightParams,
    *,
    velocities: Tensor | None = None,
    amplitudes: Tensor | None = None,
    noise_std: float = 0.0,
    generator: torch.Generator | None = None,
    chunk_elements: int = 1 << 22,
) -> Tensor:
    """Simulate deramped single-channel spotlight data ``g[b, m, k]`` of point scatterers.

    ``g = sum_i a_i exp(-j kappa_k (R_i(t_m) - R_0(t_m))) + noise`` with ``kappa_k = 4 pi f_k / c``
    and ``R_0`` the range to the scene centre (the deramp reference), i.e. dechirped data with
    residual video phase removed and deskewed, so every scatterer covers the same band. The
    slant range ``R_i(t)`` is exact (no far-field approximation) and a moving scatterer's
    position is updated per pulse. Clutter is modelled by passing many weak scatterers.
    Memory stays bounded: pulses are processed in chunks of at most ``chunk_elements``
    ``(scatterer, pulse, sample)`` terms.

    Args:
        positions: ``(B, N, 2)`` scatterer positions ``(range, azimuth)`` in m at ``t = 0``.
        params: the system (:class:`SpotlightParams`).
        velocities: optional ``(B, N, 2)`` constant velocities ``(range, azimuth)`` in m/s
            (positive range velocity = receding).
        amplitudes: optional ``(B, N)`` complex (or real) reflectivities; default 1.
        noise_std: standard deviation of circular complex white noise per sample.
        generator: random generator for the noise.
        chunk_elements: memory bound of one chunk.

    Returns:
        complex ``(B, M, K)`` phase history, M = ``params.n_pulses``, K = ``params.n_samples``;
        complex128 for float64 positions, complex64 otherwise.

    Raises:
        InputTypeError, ShapeError, OptionError: bad input.

    Shape:
        ``(B, N, 2)`` -> ``(B, M, K)``.

    References:
        C. V. Jakowatz et al., Spotlight-Mode SAR: A Signal-Processing Approach, Springer, 1996,
        ch. 2 (deramp, residual video phase, deskew).

    Example:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> p = SpotlightParams(azimuth_resolution=3.0, image_size=(64, 64))
        >>> g = simulate_phase_history(torch.zeros(2, 1, 2), p)
        >>> g.shape, bool(torch.allclose(g, torch.ones_like(g)))
        (torch.Size([2, 50, 180]), True)
    """
    _check_points(positions, velocities, amplitudes)
    noise_std = check_positive(noise_std, "noise_std", allow_zero=True)
    chunk_elements = check_int(chunk_elements, "chunk_elements", minimum=1)
    device = positions.device
    cdtype = torch.complex128 if positions.dtype == torch.float64 else torch.complex64
    b, n = positions.shape[:2]
    times = pulse_times(params, device=device)
    kappa = wavenumbers(params, device=device)
    amp = torch.ones(b, n, dtype=cdtype, device=device) if amplitudes is None else amplitudes
    amp = amp.to(torch.complex128)
    step = max(1, chunk_elements // max(1, n * kappa.numel() * max(b, 1)))
    out = []
    for start in range(0, times.numel(), step):
        t = times[start : start + step]
        dr = slant_ranges(positions, params, t, velocities) - slant_ranges(
            torch.zeros(1, 2, dtype=torch.float64, device=device), params, t
        )
        phase = torch.exp(-1j * dr[..., None] * kappa)  # (B, N, m, K)
        out.append(torch.einsum("bn,bnmk->bmk", amp, phase).to(cdtype))
    g = torch.cat(out, dim=1) if out else torch.zeros(b, 0, kappa.numel(), dtype=cdtype)
    if noise_std > 0:
        noise = torch.randn(g.shape, generator=generator, dtype=g.dtype, device=device)
        g = g + noise_std * noise  # circular: E|noise|^2 = noise_std^2
    return g
