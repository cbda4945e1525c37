"""Azimuth FM-rate (focus) correction of formed images for along-track motion.

A scatterer moving along track at ``v_a`` at slant range ``R = R0 + r`` (``r`` its range
from the scene centre) has the range history of a stationary point plus
``dR(t) = (v_a^2 - 2 V v_a) t^2 / (2 R)``: its azimuth FM rate differs and it is smeared
over ``~2 v_a T`` in azimuth. In a polar-format image whose azimuth extent is the sampled
(unambiguous) extent, azimuth spatial frequency ``f`` (cycles/m) is slow time
``t = -f lambda R0 / (2 V)`` (the scene centre's ``R0``: the image grid is referenced to it),
so the error is removed by one multiply in the azimuth spectrum of the image,
``exp(+j kappa_0 dR(t - t_c))``, taken about the look centre ``t_c`` so the focused
position does not move. The correction uses each target's own ``R`` (``ranges``); with the
scene centre's, a target 75 m off it would be misjudged by 0.75 % of its speed. Refocusing a
bank of hypotheses ``v_a`` and keeping the sharpest gives a velocity estimate independent
of the look displacement.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar._checks import check_positive
from torchsar.errors import InputTypeError, ShapeError
from torchsar.motion.params import SpotlightParams

__all__ = ["azimuth_times", "fm_correction", "focus_step", "refocus", "speed_bank"]


def azimuth_times(
    params: SpotlightParams, width: int, *, device: torch.device | str | None = None
) -> Tensor:
    """Slow time (s) of each azimuth-spectrum bin of a ``width``-pixel image row, ``(W,)``.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> t = azimuth_times(SpotlightParams.from_system(), 4)  # 150 m rows: 1 bin = 1 pulse
        >>> (t * 200).round().tolist()
        [-0.0, -1.0, 2.0, 1.0]
    """
    dx = params.image_extent[1] / width
    f = torch.fft.fftfreq(width, d=dx, dtype=torch.float64, device=device)
    return (
        -f
        * params.geometry.wavelength
        * params.track.scene_range
        / (2 * params.track.platform_speed)
    )


def refocus(
    image: Tensor,
    params: SpotlightParams,
    velocities: Tensor,
    *,
    center_time: float = 0.0,
    ranges: Tensor | None = None,
) -> Tensor:
    """Remove the azimuth FM-rate error of along-track speed ``v`` for each ``v`` of a bank.

    Args:
        image: complex ``(..., H, W)`` polar-format image(s) centred on the scene centre,
            ``W`` pixels spanning ``params.image_extent[1]``.
        params: the system.
        velocities: ``(Q,)`` hypothesised along-track speeds in m/s (0 leaves the image as is).
        center_time: centre slow time of the (look) aperture the image was formed from.
        ranges: optional range offsets ``r`` (m from the scene centre) of the targets,
            broadcastable to ``image.shape[:-2]`` (e.g. one per strip); default 0 (the
            scene centre's slant range for every row).

    Returns:
        complex ``(..., Q, H, W)``.

    Raises:
        InputTypeError, ShapeError: bad input.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> from torchsar.motion import polar_format
        >>> from torchsar.sar import simulate_phase_history
        >>> p = SpotlightParams.from_system(image_size=(64, 512))
        >>> v = torch.tensor([[[0.0, 4.0]]], dtype=torch.float64)
        >>> g = simulate_phase_history(torch.zeros(1, 1, 2), p.geometry, velocities=v)
        >>> img = polar_format(g, p)
        >>> peak = refocus(img, p, torch.tensor([0.0, 4.0])).abs().flatten(-2).amax(-1)
        >>> [round(float(a), 1) for a in peak[0]]
        [0.2, 1.0]
    """
    if not isinstance(image, Tensor) or not image.is_complex() or image.dim() < 2:
        raise InputTypeError(f"image must be a complex tensor (..., H, W), got {image!r:.60}")
    if not isinstance(velocities, Tensor) or velocities.dim() != 1:
        raise ShapeError(f"velocities must be a 1-D tensor (Q,), got {velocities!r:.60}")
    if image.numel() == 0:
        return image[..., None, :, :].expand(
            *image.shape[:-2], velocities.numel(), *image.shape[-2:]
        )
    r = None if ranges is None else torch.as_tensor(ranges, device=image.device)[..., None]
    phase = fm_correction(params, velocities, image.shape[-1], center_time, image.device, ranges=r)
    spectrum = torch.fft.fft(image, dim=-1)[..., None, :, :]
    return torch.fft.ifft(spectrum * phase[..., :, None, :].to(image.dtype), dim=-1)


def fm_correction(
    params: SpotlightParams,
    velocities: Tensor,
    width: int,
    center_time: float,
    device,
    *,
    ranges: Tensor | None = None,
) -> Tensor:
    """Complex128 azimuth-spectrum factors ``exp(+j kappa_0 dR_v(t - t_c))``, ``(..., W)``.

    One row of ``W`` factors per speed in ``velocities`` (any shape), at the scene centre's
    slant range ``R0``; with ``ranges`` (range offsets ``r`` in m, broadcastable with
    ``velocities``) each speed at its own ``R0 + r``.
    """
    t = azimuth_times(params, width, device=device) - center_time
    v = velocities.to(device=device, dtype=torch.float64)
    r = torch.tensor(params.track.scene_range, dtype=torch.float64, device=device)
    if ranges is not None:
        r = r + ranges.to(device=device, dtype=torch.float64)
    coef = (v * v - 2 * params.track.platform_speed * v) / (2 * r)
    phase = torch.remainder(
        4 * math.pi / params.geometry.wavelength * coef[..., None] * t * t, 2 * math.pi
    )
    return torch.polar(torch.ones_like(phase), phase)


def focus_step(params: SpotlightParams, aperture_time: float | None = None) -> float:
    """Speed step (m/s) that changes the quadratic phase at the aperture edge by ``4 pi``.

    The refocused peak of a mover stays within ~3 dB of its best for hypotheses within half a
    step (Hann taper), so a bank with this step detects every speed it spans.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> round(focus_step(SpotlightParams.from_system()), 3)
        0.96
    """
    t = params.geometry.aperture_time if aperture_time is None else aperture_time
    per_mps = (
        4
        * math.pi
        / params.geometry.wavelength
        * params.track.platform_speed
        * t
        * t
        / (4 * params.track.scene_range)
    )
    return 4 * math.pi / per_mps


def speed_bank(max_speed: float, step: float) -> Tensor:
    """Symmetric float64 bank ``0, +-step, +-2 step, ...`` covering ``[-max_speed, max_speed]``.

    Examples:
        >>> speed_bank(2.0, 1.0).tolist()
        [-2.0, -1.0, 0.0, 1.0, 2.0]
    """
    max_speed = check_positive(max_speed, "max_speed", allow_zero=True)
    step = check_positive(step, "step")
    n = math.ceil(max_speed / step - 1e-9)
    return torch.arange(-n, n + 1, dtype=torch.float64) * step
