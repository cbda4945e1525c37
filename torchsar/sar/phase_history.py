"""The exact phase-history simulator (stationary and moving scatterers) and its grid fast path.

``g[b, m, k] = sum_n a_n exp(-1j U_k dR_nm)``, ``dR`` the differential range of
:meth:`SpotlightGeometry.differential_ranges` (plane-wave on a polar raster, exact slant
ranges on a track), optionally times the residual video phase (RVP)
``exp(1j 4 pi gamma dR^2 / c^2)`` of deramp-on-receive. The data are evaluated on the
collection's own samples, never with the operator that reconstructs them (no inverse crime).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import partial

import torch
from torch import Tensor
from torch.nn.utils.rnn import pad_sequence

from torchsar._checks import check_complex, check_int, check_pairs
from torchsar.errors import InputTypeError, ShapeError
from torchsar.sar.geometry import SPEED_OF_LIGHT, SpotlightGeometry

__all__ = ["phase_history", "simulate_phase_history"]

_CHUNK = 1 << 22  # complex (scatterer, pulse, sample) terms per intermediate block


def _check_points(positions: object, velocities: object, amplitudes: object) -> None:
    """Validate ``(B, N, 2)`` positions, matching velocities and ``(B, N)`` amplitudes."""
    positions = check_pairs(positions, "positions", ndim=3, axes="(B, N, 2) (range, cross-range)")
    for name, x, shape in (
        ("velocities", velocities, positions.shape),
        ("amplitudes", amplitudes, positions.shape[:2]),
    ):
        if x is not None and (not isinstance(x, Tensor) or x.shape != shape):
            got = tuple(x.shape) if isinstance(x, Tensor) else type(x).__name__
            raise ShapeError(f"{name} must have shape {tuple(shape)}, got {got}")


def _pad_scenes(
    positions: Sequence[Tensor], velocities: object, amplitudes: object
) -> tuple[Tensor, Tensor | None, Tensor]:
    """Scenes of unequal sizes as one ``(B, N, 2)`` batch; padding scatterers get amplitude 0.

    ``velocities`` / ``amplitudes`` are ``None`` or sequences of tensors matching ``positions``.
    """
    for name, seq in (("velocities", velocities), ("amplitudes", amplitudes)):
        if seq is not None and (
            isinstance(seq, Tensor) or not isinstance(seq, Sequence) or len(seq) != len(positions)
        ):
            raise InputTypeError(
                f"{name} must be None or a sequence of {len(positions)} tensors like positions, "
                f"got {type(seq).__name__}"
            )
    for i, p in enumerate(positions):
        check_pairs(p, f"positions[{i}]", ndim=2, axes="(N_b, 2) (range, cross-range)")
        for name, seq, shape in (
            ("velocities", velocities, p.shape),
            ("amplitudes", amplitudes, p.shape[:1]),
        ):
            x = None if seq is None else seq[i]  # type: ignore[index]
            if seq is not None and (not isinstance(x, Tensor) or x.shape != shape):
                got = tuple(x.shape) if isinstance(x, Tensor) else type(x).__name__
                raise ShapeError(f"{name}[{i}] must have shape {tuple(shape)}, got {got}")
    if not positions:
        return torch.zeros(0, 0, 2), None, torch.zeros(0, 0)
    ones = [p.new_ones(p.shape[0]) for p in positions]
    pad = partial(pad_sequence, batch_first=True)  # zeros beyond each scene's N_b
    vel = None if velocities is None else pad(list(velocities))  # type: ignore[arg-type]
    return pad(list(positions)), vel, pad(list(amplitudes or ones))  # type: ignore[arg-type]


def _result_dtype(positions: Tensor, amplitudes: Tensor | None) -> torch.dtype:
    """complex128 when positions or amplitudes are double precision, else complex64."""
    double = positions.dtype == torch.float64 or (
        amplitudes is not None and amplitudes.dtype in (torch.float64, torch.complex128)
    )
    return torch.complex128 if double else torch.complex64


def simulate_phase_history(
    positions: Tensor | Sequence[Tensor],
    geometry: SpotlightGeometry,
    *,
    velocities: Tensor | Sequence[Tensor] | None = None,
    amplitudes: Tensor | Sequence[Tensor] | None = None,
    rvp: bool = False,
    chunk_elements: int = _CHUNK,
) -> Tensor:
    """Deramped spotlight phase history ``g[b, m, k]`` of point scatterers (exact model).

    ``g = sum_n a_n exp(-1j U_k dR_n(m)) [* exp(1j 4 pi gamma dR^2 / c^2)]`` with
    ``U_k = 4 pi f_k / c`` and ``dR`` the differential range to the scene centre (the
    deramp reference): on a track the exact slant range, a moving scatterer's position
    updated per pulse; on a polar raster the plane-wave projection. Clutter is modelled by
    passing many weak scatterers; noise is added by :func:`~torchsar.sar.add_noise`.
    Memory stays bounded: pulses are processed in chunks of at most ``chunk_elements``
    ``(scatterer, pulse, sample)`` terms (the result does not depend on the chunking).

    Scenes with different numbers of scatterers go in one call as sequences: ``positions``
    a list of ``(N_b, 2)`` tensors, ``velocities`` and ``amplitudes`` (when given) lists of
    ``(N_b, 2)`` and ``(N_b,)`` tensors; scene ``b`` gives the same data as a call with its
    scatterers alone.

    Args:
        positions: real ``(B, N, 2)`` positions ``(range, cross-range)`` in m at ``t = 0``,
            or a sequence of ``B`` tensors ``(N_b, 2)``.
        geometry: the collection (:class:`~torchsar.sar.SpotlightGeometry`).
        velocities: optional ``(B, N, 2)`` constant velocities in m/s (positive range
            velocity = receding), or a sequence like ``positions``; needs
            ``geometry.track``. Default: stationary.
        amplitudes: optional ``(B, N)`` complex (or real) reflectivities (or a sequence of
            ``(N_b,)``); default 1.
        rvp: include the residual video phase (uses ``geometry.chirp_rate``).
        chunk_elements: memory bound of one chunk.

    Returns:
        complex ``(B, M, K)``; complex128 when ``positions`` or ``amplitudes`` are double
        precision, complex64 otherwise.

    Raises:
        InputTypeError, ShapeError, OptionError: bad input.

    Shape:
        ``(B, N, 2)`` -> ``(B, M, K)``.

    References:
        C. V. Jakowatz et al., Spotlight-Mode SAR: A Signal-Processing Approach, Springer, 1996,
        doi:10.1007/978-1-4613-1333-5, ch. 2 (deramp, residual video phase, deskew);
        Önhon & Çetin, SIU 2009, doi:10.1109/SIU.2009.5136449.

    Examples:
        >>> geo = SpotlightGeometry.for_image((4, 4))
        >>> g = simulate_phase_history(torch.zeros(2, 1, 2), geo)
        >>> g.shape, bool(torch.allclose(g, torch.ones_like(g)))
        (torch.Size([2, 4, 4]), True)
        >>> ragged = simulate_phase_history([torch.zeros(1, 2), torch.zeros(3, 2)], geo)
        >>> ragged[:, 0, 0].real.tolist()  # one and three unit scatterers at the centre
        [1.0, 3.0]
    """
    if isinstance(positions, Sequence):
        positions, velocities, amplitudes = _pad_scenes(positions, velocities, amplitudes)
    _check_points(positions, velocities, amplitudes)
    chunk_elements = check_int(chunk_elements, "chunk_elements", minimum=1)
    device = positions.device
    b, n = positions.shape[:2]
    m_n, k_n = geometry.pulses, geometry.samples
    kappa = geometry.wavenumbers(device=device)
    amp = (
        torch.ones(b, n, dtype=torch.complex128, device=device)
        if amplitudes is None
        else amplitudes.to(device=device, dtype=torch.complex128)
    )
    rvp_rate = 4 * math.pi * geometry.chirp_rate / SPEED_OF_LIGHT**2 if rvp else 0.0
    out = torch.empty(b, m_n, k_n, dtype=_result_dtype(positions, amplitudes), device=device)
    step = max(1, chunk_elements // max(1, n * k_n * max(b, 1)))
    for start in range(0, m_n, step):
        pulses = slice(start, start + step)
        dr = geometry.differential_ranges(positions, velocities=velocities, pulses=pulses)
        phase = -dr[..., None] * kappa  # (B, N, m, K)
        if rvp:
            phase = phase + rvp_rate * dr[..., None] ** 2
        terms = torch.polar(torch.ones_like(phase), phase)
        out[:, pulses] = torch.einsum("bn,bnmk->bmk", amp, terms)
    return out


def phase_history(scene: Tensor, geometry: SpotlightGeometry, *, rvp: bool = False) -> Tensor:
    """Phase history of a reflectivity image on the polar-raster pixel grid (exact model).

    Pixel ``(i, j)`` is a scatterer at cross-range ``y_i`` and range ``x_j`` of
    :meth:`SpotlightGeometry.pixel_positions`. The result is scaled by ``1/sqrt(M K)`` so
    that on a narrow-angle polar raster it approximates :class:`~torchsar.imaging.FourierOperator`
    (unitary) data. A stationary polar raster without RVP uses the separable fast path
    ``exp(-j(kx x + ky y)) = exp(-j kx x) exp(-j ky y)`` (tested equal to
    :func:`simulate_phase_history`); anything else is the point sum itself.

    Args:
        scene: complex reflectivity ``(B, 1, H, W)``.
        geometry: the collection (``M`` pulses, ``K`` samples, pixel spacing).
        rvp: include the residual video phase (needs ``geometry.chirp_rate``).

    Returns:
        Complex phase history ``(B, M, K)`` in ``scene``'s dtype.

    Raises:
        InputTypeError, ShapeError: ``scene`` is not a complex ``(B, 1, H, W)`` tensor.

    Shape:
        ``(B, 1, H, W) -> (B, M, K)``.

    Examples:
        >>> geo = SpotlightGeometry.for_image((8, 8))
        >>> f = torch.zeros(1, 1, 8, 8, dtype=torch.complex64); f[0, 0, 4, 4] = 1
        >>> g = phase_history(f, geo)
        >>> torch.allclose(g.abs(), torch.full((1, 8, 8), 1 / 8.0))
        True
    """
    scene = check_complex(scene, "scene", ndim=4)
    if scene.shape[1] != 1:
        raise ShapeError(f"scene must have one channel (B, 1, H, W), got {tuple(scene.shape)}")
    if rvp or geometry.track is not None:
        return _grid_as_points(scene, geometry, rvp)
    return _separable_sum(scene[:, 0], geometry)


def _separable_sum(f: Tensor, geometry: SpotlightGeometry) -> Tensor:
    """Exact polar-raster sum using ``exp(-j(kx x + ky y)) = exp(-j kx x) exp(-j ky y)``."""
    b, h, w = f.shape
    m, k = geometry.pulses, geometry.samples
    u = geometry.wavenumbers(device=f.device)
    th = geometry.angles(device=f.device)
    kx, ky = torch.outer(th.cos(), u), torch.outer(th.sin(), u)  # (M, K) each
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


def _grid_as_points(scene: Tensor, geometry: SpotlightGeometry, rvp: bool) -> Tensor:
    """:func:`simulate_phase_history` of every pixel of ``scene``, scaled like the fast path."""
    b, _, h, w = scene.shape
    y, x = geometry.pixel_positions((h, w), device=scene.device)
    yy, xx = torch.meshgrid(y, x, indexing="ij")
    amps = scene.reshape(b, h * w)
    pos = torch.stack([xx.reshape(-1), yy.reshape(-1)], -1).expand(b, h * w, 2)
    g = simulate_phase_history(pos, geometry, amplitudes=amps, rvp=rvp)
    return (g / (geometry.pulses * geometry.samples) ** 0.5).to(scene.dtype)
