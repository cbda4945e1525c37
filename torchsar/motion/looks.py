"""Time sub-aperture (look) images: the same scene seen over successive parts of the aperture.

Look ``k`` is formed from pulses ``start_k .. stop_k - 1`` only, by the polar-format
algorithm restricted to those pulses (its own taper, its own k-space grid), so it costs one
image formation of ``stop_k - start_k`` pulses and no zero-filled full-size array. All looks
share the pixel grid of the full image. A stationary scatterer appears at the same pixel in
every look; a scatterer moving along track at ``v_a`` appears displaced between looks whose
centre times differ by ``dt`` by ``dx = (2 v_a - v_a^2 / V) dt`` (:func:`look_displacement`).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar._checks import check_int, check_positive
from torchsar.errors import OptionError
from torchsar.motion.formation import polar_format
from torchsar.motion.params import SpotlightParams

__all__ = ["LookPlan", "look_displacement", "look_images", "look_plan", "look_velocity"]


@dataclass(frozen=True)
class LookPlan:
    """Pulse ranges and centre times of ``K`` looks.

    Attributes:
        start: long ``(K,)`` first pulse of each look.
        stop: long ``(K,)`` one past the last pulse.
        time: float64 ``(K,)`` centre slow time of each look in s (0 = aperture centre).
    """

    start: Tensor
    stop: Tensor
    time: Tensor


def look_plan(params: SpotlightParams, *, looks: int = 2, overlap: float = 0.0) -> LookPlan:
    """Split the aperture into ``looks`` equal sub-apertures overlapping by ``overlap``.

    The look length is ``L = floor(M / (1 + (K - 1) (1 - overlap)))`` pulses; the looks are
    spread evenly from the first to the last pulse.

    Args:
        params: the system (``M = params.geometry.pulses``).
        looks: number of looks ``K >= 1``.
        overlap: fraction of a look shared with the next one, in ``[0, 1)``.

    Returns:
        :class:`LookPlan`.

    Raises:
        OptionError: ``looks < 1``, ``overlap`` outside ``[0, 1)``, or looks of < 2 pulses.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> plan = look_plan(SpotlightParams.from_system(), looks=2)
        >>> plan.start.tolist(), plan.stop.tolist(), plan.time.tolist()
        ([0, 250], [250, 500], [-0.625, 0.625])
    """
    k = check_int(looks, "looks", minimum=1)
    overlap = check_positive(overlap, "overlap", allow_zero=True)
    if overlap >= 1:
        raise OptionError(f"overlap must be in [0, 1), got {overlap!r}")
    m = params.geometry.pulses
    length = int(m // (1 + (k - 1) * (1 - overlap)))
    if length < 2:
        raise OptionError(f"looks = {k} leaves {length} pulse(s) per look (of {m}); use fewer")
    start = torch.tensor([round(i * (m - length) / max(k - 1, 1)) for i in range(k)])
    stop = start + length
    t = params.geometry.pulse_times()
    time = torch.stack([t[a:b].mean() for a, b in zip(start.tolist(), stop.tolist(), strict=True)])
    return LookPlan(start, stop, time)


def look_images(
    phase_history: Tensor,
    params: SpotlightParams,
    *,
    looks: int = 2,
    overlap: float = 0.0,
    size: tuple[int, int] | None = None,
    window: str = "hann",
) -> Tensor:
    """Form one complex image per look (time sub-aperture), on the full image's pixel grid.

    Args:
        phase_history: complex ``(B, M, K)`` deramped on the scene centre.
        params: the system.
        looks: number of looks (see :func:`look_plan`).
        overlap: fraction of a look shared with the next one.
        size: ``(H, W)`` pixels; default ``params.image_size``.
        window: k-space taper of each look (``"hann"`` or ``"none"``).

    Returns:
        complex ``(B, looks, H, W)``; look ``k`` spans the pulses of ``look_plan(...)``.

    Raises:
        InputTypeError, ShapeError, OptionError: bad input.

    Shape:
        ``(B, M, K)`` -> ``(B, looks, H, W)``.

    References:
        K. Ouchi, "On the multilook images of moving targets by synthetic aperture radars",
        IEEE Trans. Antennas Propag. 33(8), 1985, doi:10.1109/TAP.1985.1143684.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> from torchsar.sar import simulate_phase_history
        >>> p = SpotlightParams.from_system(azimuth_resolution=1.0, image_size=(64, 64))
        >>> g = simulate_phase_history(torch.zeros(2, 1, 2), p.geometry)
        >>> x = look_images(g, p, looks=3, overlap=0.5)
        >>> x.shape, [divmod(int(i), 64) for i in x[0].abs().flatten(1).argmax(1)]
        (torch.Size([2, 3, 64, 64]), [(32, 32), (32, 32), (32, 32)])
    """
    plan = look_plan(params, looks=looks, overlap=overlap)
    images = [
        polar_format(phase_history[:, a:b], params, size=size, window=window, pulses=(a, b))
        for a, b in zip(plan.start.tolist(), plan.stop.tolist(), strict=True)
    ]
    return torch.stack(images, dim=1)


def look_displacement(
    velocity: Tensor | float,
    dt: Tensor | float,
    params: SpotlightParams,
    *,
    ranges: Tensor | float = 0.0,
):
    """Image azimuth displacement of an along-track mover between looks ``dt`` apart.

    The look formed around slow time ``t_c`` focuses a scatterer where its Doppler rate
    history matches a stationary point's at ``t_c``; for a mover at ``v_a`` (along the
    platform track, platform speed ``V``) that point moves by ``2 v_a - v_a^2 / V`` per second
    of look time: the first-order law is twice the ground motion ``v_a dt``. The image's
    azimuth axis is referenced to the scene centre's slant range ``R0``, so a scatterer at
    range offset ``r`` is drawn ``R0 / (R0 + r)`` times its azimuth offset: the image
    displacement is ``(2 v_a - v_a^2 / V) dt R0 / (R0 + r)``.

    Args:
        velocity: along-track speed ``v_a`` (m/s).
        dt: look time difference (s).
        params: the system.
        ranges: range offset ``r`` of the scatterer from the scene centre (m).

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> round(look_displacement(4.0, 1.25, SpotlightParams.from_system()), 4)
        9.9
    """
    scale = params.track.scene_range / (params.track.scene_range + ranges)
    return (2 * velocity - velocity * velocity / params.track.platform_speed) * dt * scale


def look_velocity(
    displacement_rate: Tensor, params: SpotlightParams, *, ranges: Tensor | float = 0.0
) -> Tensor:
    """Invert :func:`look_displacement`: ``v_a`` from the image displacement per second.

    ``v_a = V (1 - sqrt(1 - r' / V))``, ``r' = rate (R0 + r) / R0`` (the root near zero;
    ``r'`` clipped to ``<= V``).

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> round(float(look_velocity(torch.tensor(7.92), SpotlightParams.from_system())), 4)
        4.0
    """
    v = params.track.platform_speed
    rate = displacement_rate * (1 + ranges / params.track.scene_range)
    return v * (1 - torch.sqrt((1 - rate / v).clamp(min=0)))
