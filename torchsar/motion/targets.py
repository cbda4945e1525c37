"""Point targets in a full-aperture image, movers included: detection over a speed bank."""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
from torch import Tensor

from torchsar.cfar import Detection
from torchsar.motion.focus import fm_correction, focus_step, speed_bank
from torchsar.motion.params import HANN_BROADENING, SpotlightParams
from torchsar.motion.peaks import default_detector, intensity, window_max

__all__ = ["bank_detect", "detect_targets", "smear_ghosts"]


def bank_detect(
    image: Tensor,
    params: SpotlightParams,
    speeds: Tensor,
    detector: Callable[[Tensor], Detection],
) -> tuple[Tensor, Tensor]:
    """Refocus ``image (B, H, W)`` for each speed; OR of the detections, max of the intensities.

    Returns:
        ``(mask, best)``: bool and float ``(B, 1, H, W)``.
    """
    best = intensity(image)[:, None]
    mask = detector(best).mask
    if image.numel() == 0:
        return mask, best
    spectrum = torch.fft.fft(image, dim=-1)
    for v in speeds[speeds != 0]:
        phase = fm_correction(params, v[None], image.shape[-1], 0.0, image.device)
        x = intensity(torch.fft.ifft(spectrum * phase.to(image.dtype), dim=-1))[:, None]
        mask = mask | detector(x).mask
        best = torch.maximum(best, x)
    return mask, best


def detect_targets(
    image: Tensor,
    params: SpotlightParams,
    *,
    max_speed: float = 16.0,
    detector: Callable[[Tensor], Detection] | None = None,
    pfa: float = 1e-6,
    max_targets: int = 64,
) -> tuple[Tensor, Tensor]:
    """Point targets of a full-aperture image refocused over a bank of along-track speeds.

    The image is refocused for speeds ``0, +-s, +-2s, ... <= max_speed`` with
    ``s = 1.5 focus_step(params)`` (every mover within ~5 dB of its focused peak); each refocused
    image is searched by the CFAR ``detector`` (default: CA-CFAR sized to the resolution at
    ``pfa / Q`` for ``Q`` speeds, so the bank keeps the overall ``pfa``); a target is a pixel
    detected at some speed that is the brightest over the bank within two resolution cells.
    A bright target refocused for a wrong speed is smeared along its row: peaks such a smear
    explains are dropped (:func:`smear_ghosts`).

    Args:
        image: complex ``(B, H, W)`` full-aperture image centred on the scene centre.
        params: the system.
        max_speed: largest along-track speed (m/s) the bank covers (0 = no bank).
        detector: intensity ``(B, 1, H, W)`` -> :class:`~torchsar.cfar.Detection`.
        pfa: design false-alarm probability per pixel of the default detector.
        max_targets: at most this many (brightest) targets per scene.

    Returns:
        ``(pixel, valid)``: long ``(B, N, 2)`` target pixels sorted by decreasing intensity
        (-1 for padding) and bool ``(B, N)``.
    """
    h, w = image.shape[-2:]
    res_px = (
        params.geometry.range_resolution * h / params.image_extent[0],
        params.geometry.cross_range_resolution * w / params.image_extent[1],
    )
    speeds = speed_bank(max_speed, 1.5 * focus_step(params)).to(image.device)
    if detector is None:
        detector = default_detector(res_px, pfa=pfa / speeds.numel())
    mask, best = bank_detect(image, params, speeds, detector)
    radius = max(1, math.ceil(2 * max(res_px)))
    peaks = (mask & (best == window_max(best, radius)))[:, 0]
    lists = []
    for b in range(image.shape[0]):
        value = best[b, 0][peaks[b]]
        order = value.argsort(descending=True)
        pix, value = peaks[b].nonzero()[order], value[order]
        keep = ~smear_ghosts(pix, value, res_px, w)
        lists.append(pix[keep][:max_targets])
    n = max([len(x) for x in lists], default=0)
    pixel = torch.full((image.shape[0], n, 2), -1, dtype=torch.long, device=image.device)
    for b, x in enumerate(lists):
        pixel[b, : len(x)] = x
    return pixel, pixel[..., 0] >= 0


def smear_ghosts(pixel: Tensor, value: Tensor, res_px: tuple[float, float], width: int) -> Tensor:
    """Peaks explained by the smear of a brighter peak in the same range cell.

    A target of intensity ``I`` refocused for a wrong speed spreads over ``L`` m of its
    row, about ``I rho / L`` per resolution cell ``rho``; a peak ``d`` columns away within
    one range resolution cell and weaker than ``2 I rho / d`` (Hann-broadened ``rho``) may
    be such a smear and is dropped (a weaker genuine target there is masked: a documented
    limitation).

    Args:
        pixel: long ``(n, 2)`` peaks sorted by decreasing ``value``.
        value: ``(n,)`` bank intensity at each peak.
        res_px: ``(range, azimuth)`` resolution in pixels.
        width: image width (columns are periodic).

    Returns:
        bool ``(n,)``.

    Example:
        >>> pix = torch.tensor([[10, 100], [10, 140], [40, 140]])
        >>> smear_ghosts(pix, torch.tensor([1e4, 50.0, 50.0]), (2.0, 2.0), 512).tolist()
        [False, True, False]
    """
    d_row = (pixel[:, None, 0] - pixel[None, :, 0]).abs()
    d_col = (pixel[:, None, 1] - pixel[None, :, 1]).remainder(width)
    d_col = torch.minimum(d_col, width - d_col).clamp(min=1).double()
    rho = HANN_BROADENING * res_px[1]
    explained = (d_row <= HANN_BROADENING * res_px[0]) & (
        value[:, None].double() < 2 * value[None, :].double() * rho / d_col
    )
    brighter = torch.ones_like(explained).tril(-1)  # column q < row p: q is brighter
    return (explained & brighter).any(1)
