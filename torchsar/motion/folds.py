"""Doppler folds: what one channel sees of a fast radial mover, and how to undo its range walk.

To first order a scatterer at ``(r, x)`` moving in range at ``v_r`` (receding > 0) has the
phase history of a stationary point at the *apparent* azimuth ``x' = x - R v_r / V``
(``R = R0 + r`` its slant range, ``V`` the platform speed). The pulses sample azimuth with
period ``P_R = lambda PRF R / (2 V)`` (the sampled extent, ``P_R0 = 150`` m for Table 1): a
scatterer is *folded* when ``|x'| > P_R / 2`` and is then shown at ``x' - k P_R``, Doppler
fold ``k = round(x' / P_R)``. So whether a radial mover folds depends on where it is, not
on its speed alone: it folds when ``|x - R v_r / V|`` exceeds half the sampled extent
(``|v_r| > lambda PRF / 4 = 1.5`` m/s at the scene centre of Table 1, less on one side of
it and more on the other; a *stationary* scatterer beyond the sampled extent folds too).

Polar formatting compensates the range walk ``-V x_s t / R`` of the position ``x_s`` it
shows, not the scatterer's own ``-V x' t / R``: a residual range walk of
``-V k P_R / R = -k lambda PRF / 2`` m per second of slow time remains, whatever the range
(3 m/s per fold for Table 1, :func:`walk_rate`). Looks ``dt`` apart see the scatterer
``k lambda PRF dt / 2`` apart in range (3.75 m per fold for two looks of a 2.5 s
aperture), and the full-aperture image smears it over ``|k| lambda PRF T / 2`` in range
(7.5 m per fold) at the azimuth where it is shown: the single-channel signature of a fast
radial mover, first order and strong. An unfolded one (``k = 0``) is exactly a displaced
stationary point and shows nothing. The walk gives ``k``, not ``v_r``: the scatterer's true
azimuth is unknown, and every ``x`` in the scene gives another ``v_r``
(:func:`radial_speed_interval`).

:func:`unwalk` undoes the residual walk of a hypothesised fold: in the image's 2-D spectrum,
azimuth frequency is slow time (:func:`~torchsar.motion.focus.azimuth_times`), and the
component at time ``t`` is shifted back by ``k lambda PRF (t - t_c) / 2`` in range.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar._checks import check_pairs
from torchsar.errors import InputTypeError, ShapeError
from torchsar.motion.focus import azimuth_times
from torchsar.motion.params import SpotlightParams

__all__ = ["doppler_fold", "radial_speed_interval", "unwalk", "walk_correction", "walk_rate"]


def walk_rate(fold: Tensor | float, params: SpotlightParams) -> Tensor | float:
    """Residual range walk ``-k lambda PRF / 2`` (m/s) of a scatterer folded ``k`` times.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> round(walk_rate(-1, SpotlightParams.from_system()), 3)  # m/s, Table 1
        2.998
    """
    return -fold * params.geometry.blind_speed


def doppler_fold(
    positions: Tensor, params: SpotlightParams, *, velocities: Tensor | None = None
) -> Tensor:
    """Doppler fold ``k = round(x' / P_R)`` of scatterers (first order), long ``(...)``.

    Args:
        positions: ``(..., 2)`` ``(range, azimuth)`` at ``t = 0`` in m.
        params: the system.
        velocities: optional ``(..., 2)`` ``(v_r, v_a)`` in m/s (default stationary).

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> p = SpotlightParams.from_system()
        >>> pos = torch.tensor([[20.0, 10.0], [20.0, 10.0], [0.0, 90.0]])
        >>> vel = torch.tensor([[1.1, 0.0], [1.9, 0.0], [0.0, 0.0]])
        >>> doppler_fold(pos, p, velocities=vel).tolist()  # a stationary point beyond 75 m folds
        [0, -1, 1]
    """
    pos = check_pairs(positions, "positions", ndim=positions.dim(), axes="(..., 2)").double()
    rng = params.track.scene_range + pos[..., 0]
    apparent = pos[..., 1]
    if velocities is not None:
        vel = velocities.to(pos)
        apparent = apparent - (rng * vel[..., 0] + pos[..., 1] * vel[..., 1]) / (
            params.track.platform_speed
        )
    period = params.geometry.unambiguous_azimuth * rng / params.track.scene_range
    return torch.floor(apparent / period + 0.5).long()


def radial_speed_interval(fold: Tensor, position: Tensor, params: SpotlightParams) -> Tensor:
    """Radial speeds ``(..., 2)`` (lowest, highest; m/s) of a scatterer shown at ``position``
    with fold ``fold``, wherever it is within the scene's azimuth extent.

    The image shows the scatterer at ``x_s`` (m in the image, ``x_s R / R0`` on the ground at
    range ``R``); its true azimuth ``x`` lies in ``+-params.scene_extent[1] / 2``, so
    ``v_r = V (x - x_s R / R0) / R - k lambda PRF / 2`` spans ``V W_az / R`` (4 m/s for
    Table 1) around ``-k lambda PRF / 2 - V x_s / R0``.

    Args:
        fold: long ``(...)`` fold numbers.
        position: ``(..., 2)`` image ``(range, azimuth)`` positions in m.
        params: the system.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> p = SpotlightParams.from_system()
        >>> pos = torch.tensor([[19.7, 65.0]], dtype=torch.float64)  # 1.9 m/s shown at +65 m
        >>> radial_speed_interval(torch.tensor([-1]), pos, p).round(decimals=1).tolist()
        [[-0.3, 3.7]]
    """
    pos = position.double()
    rng = params.track.scene_range + pos[..., 0]
    ground = pos[..., 1] * rng / params.track.scene_range
    half = params.scene_extent[1] / 2
    base = -fold.to(pos) * params.geometry.blind_speed
    scale = params.track.platform_speed / rng
    return torch.stack([base + scale * (-half - ground), base + scale * (half - ground)], dim=-1)


def walk_correction(
    params: SpotlightParams,
    folds: Tensor,
    shape: tuple[int, int],
    row_spacing: float,
    center_time: float,
    device=None,
) -> Tensor:
    """Complex128 2-D spectrum factors ``(..., S, W)`` undoing the walk of each fold.

    ``exp(-2j pi f_y k lambda PRF (t(f_x) - t_c) / 2)`` on the ``fft2`` grid of an
    ``S x W`` image whose rows are ``row_spacing`` m apart and whose ``W`` columns span
    ``params.image_extent[1]``; ``folds`` any shape.
    """
    s, w = shape
    f_y = torch.fft.fftfreq(s, d=row_spacing, dtype=torch.float64, device=device)
    t = azimuth_times(params, w, device=device) - center_time
    k = folds.to(device=device, dtype=torch.float64)[..., None, None]
    shift = k * params.geometry.blind_speed * t  # m, per azimuth bin
    return torch.polar(torch.ones_like(shift * f_y[:, None]), -2 * math.pi * f_y[:, None] * shift)


def unwalk(
    image: Tensor,
    params: SpotlightParams,
    folds: Tensor,
    *,
    row_spacing: float | None = None,
    center_time: float = 0.0,
) -> Tensor:
    """Undo the residual range walk of fold ``k`` for each ``k`` of a bank.

    Each slow-time component of the image is moved back in range by the walk it had at
    that time (about ``center_time``, so a scatterer of that fold is compacted where it
    was shown at ``center_time``, without moving).

    Args:
        image: complex ``(..., S, W)`` image or full-width strips (``W`` columns spanning
            ``params.image_extent[1]``).
        params: the system.
        folds: ``(Q,)`` hypothesised folds (0 leaves the image as is).
        row_spacing: m between rows; default ``params.image_extent[0] / S`` (a whole image).
        center_time: centre slow time of the (look) aperture the image was formed from.

    Returns:
        complex ``(..., Q, S, W)``.

    Raises:
        InputTypeError, ShapeError: bad input.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> from torchsar.motion import polar_format
        >>> from torchsar.sar import simulate_phase_history
        >>> p = SpotlightParams.from_system(image_size=(256, 512))
        >>> pos = torch.tensor([[[20.0, 10.0]]]); vel = torch.tensor([[[1.9, 0.0]]])  # fold -1
        >>> img = polar_format(simulate_phase_history(pos, p.geometry, velocities=vel), p)
        >>> peak = unwalk(img, p, torch.tensor([0, -1])).abs().flatten(-2).amax(-1)
        >>> [round(float(a), 1) for a in peak[0]]
        [0.5, 0.9]
    """
    if not isinstance(image, Tensor) or not image.is_complex() or image.dim() < 2:
        raise InputTypeError(f"image must be a complex tensor (..., S, W), got {image!r:.60}")
    if not isinstance(folds, Tensor) or folds.dim() != 1:
        raise ShapeError(f"folds must be a 1-D tensor (Q,), got {folds!r:.60}")
    s, w = image.shape[-2:]
    dy = params.image_extent[0] / s if row_spacing is None else row_spacing
    factor = walk_correction(params, folds, (s, w), dy, center_time, image.device)
    spectrum = torch.fft.fft2(image)[..., None, :, :]
    return torch.fft.ifft2(spectrum * factor.to(image.dtype))
