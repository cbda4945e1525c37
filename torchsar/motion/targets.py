"""Point targets in a full-aperture image, movers included: detection over a motion bank.

The bank holds the image refocused for a set of along-track speeds (fold 0) and unwalked
for a set of Doppler folds (speed 0): every target is compact in the bank image of its own
motion, and its response in any other bank image is a streak of known direction and
length (:func:`smear_ghosts`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar.cfar import Detection
from torchsar.motion.focus import fm_correction, focus_step, speed_bank
from torchsar.motion.folds import walk_correction
from torchsar.motion.params import SpotlightParams
from torchsar.motion.peaks import default_detector, intensity, window_max
from torchsar.motion.streaks import streak_level
from torchsar.motion.strips import background

__all__ = [
    "GHOST_MARGIN",
    "GHOST_NOISE",
    "Bank",
    "Targets",
    "bank_detect",
    "detect_targets",
    "smear_ghosts",
]

# Streak intensity multiple still explained: simulated streaks reach 1.4 times the model
# (ripples; tests/motion/test_streaks.py).
GHOST_MARGIN = 2.0
# Intensity a bank peak may owe to noise, in mean background intensities: about the largest
# of a few hundred exponential samples (~30 bank images around a peak: ln 300 = 5.7),
# rounded up.
GHOST_NOISE = 8.0


@dataclass(frozen=True)
class Bank:
    """Output of :func:`bank_detect`; all ``(B, 1, H, W)``.

    Attributes:
        mask: bool, detected in some bank image.
        best: the largest intensity over the bank.
        speed: float64 along-track speed (m/s) of the bank image giving ``best``.
        fold: long Doppler fold of that image.
    """

    mask: Tensor
    best: Tensor
    speed: Tensor
    fold: Tensor


@dataclass(frozen=True)
class Targets:
    """Output of :func:`detect_targets`; per-target fields ``(B, N)`` (padding: invalid).

    Attributes:
        pixel: long ``(B, N, 2)`` target pixels sorted by decreasing bank intensity (-1 for
            padding).
        valid: bool ``(B, N)``.
        value: bank intensity at the pixel (0 for padding).
        speed: float64 speed of the bank image where the target is brightest (m/s).
        fold: long fold of that image.
    """

    pixel: Tensor
    valid: Tensor
    value: Tensor
    speed: Tensor
    fold: Tensor


def _bank_images(image: Tensor, params: SpotlightParams, speeds: list, folds: list):
    """Intensities ``(B, 1, H, W)`` of the non-trivial bank images, speeds first, then folds."""
    h, w = image.shape[-2:]
    spectrum = torch.fft.fft(image, dim=-1)
    if speeds:
        phase = fm_correction(params, torch.tensor(speeds), w, 0.0, image.device)
        for row in phase.to(image.dtype):
            yield intensity(torch.fft.ifft(spectrum * row, dim=-1))[:, None]
    if folds:
        spectrum2 = torch.fft.fft(spectrum, dim=-2)
        factor = walk_correction(
            params, torch.tensor(folds), (h, w), params.image_extent[0] / h, 0.0, image.device
        )
        for f in factor.to(image.dtype):
            yield intensity(torch.fft.ifft2(spectrum2 * f))[:, None]


def bank_detect(
    image: Tensor,
    params: SpotlightParams,
    speeds: Tensor,
    detector: Callable[[Tensor], Detection],
    *,
    folds: Tensor | None = None,
) -> Bank:
    """Detect on every bank image of ``image (B, H, W)``: OR of the masks, max of intensities.

    The bank is the image refocused for each of ``speeds``
    (:func:`~torchsar.motion.focus.fm_correction`, at the scene centre's slant range: over
    +-90 m of range that misjudges a speed by under 1 %, well inside the bank's spacing; the
    focus and look tests estimate at each target's own range) and unwalked for each of
    ``folds`` (:func:`~torchsar.motion.folds.unwalk`); speed 0 / fold 0 is the image itself.

    Returns:
        :class:`Bank`.
    """
    best = intensity(image)[:, None]
    mask = detector(best).mask
    folds = torch.zeros(0, dtype=torch.long) if folds is None else folds.cpu()
    v = [x for x in speeds.cpu().tolist() if x != 0]
    k = [x for x in folds.tolist() if x != 0]
    which = torch.zeros(best.shape, dtype=torch.uint8, device=best.device)  # 0: the image
    if image.numel():
        for q, x in enumerate(_bank_images(image, params, v, k), start=1):
            mask |= detector(x).mask
            which = torch.where(x > best, q, which)
            best = torch.maximum(best, x)
    table_v = torch.tensor([0.0, *v, *[0.0] * len(k)], dtype=torch.float64, device=best.device)
    table_k = torch.tensor([0, *[0] * len(v), *k], dtype=torch.long, device=best.device)
    return Bank(mask, best, table_v[which.long()], table_k[which.long()])


def detect_targets(
    image: Tensor,
    params: SpotlightParams,
    *,
    max_speed: float = 16.0,
    max_fold: int = 0,
    detector: Callable[[Tensor], Detection] | None = None,
    pfa: float = 1e-6,
    max_targets: int = 64,
    window: str = "hann",
) -> Targets:
    """Point targets of a full-aperture image refocused over a bank of motions.

    The image is refocused for speeds ``0, +-s, +-2s, ... <= max_speed`` with
    ``s = 1.5 focus_step(params)`` (every mover within ~5 dB of its focused peak) and
    unwalked for folds ``+-1 .. +-max_fold``; each bank image is searched by the CFAR
    ``detector`` (default: CA-CFAR sized to the resolution at ``pfa / Q`` for ``Q`` bank
    images, so the bank keeps the overall ``pfa``); a target is a pixel detected in some
    image that is the brightest over the bank within two resolution cells. A bright target
    in a bank image of the wrong motion is a streak: peaks such a streak explains are
    dropped (:func:`smear_ghosts`).

    Args:
        image: complex ``(B, H, W)`` full-aperture image centred on the scene centre.
        params: the system.
        max_speed: largest along-track speed (m/s) the bank covers (0 = no speeds).
        max_fold: largest Doppler fold the bank covers (0 = no folds).
        detector: intensity ``(B, 1, H, W)`` -> :class:`~torchsar.cfar.Detection`.
        pfa: design false-alarm probability per pixel of the default detector.
        max_targets: at most this many (brightest) targets per scene.
        window: the image-formation taper (shapes the streaks).

    Returns:
        :class:`Targets`.
    """
    h, w = image.shape[-2:]
    res_px = (
        params.geometry.range_resolution * h / params.image_extent[0],
        params.geometry.cross_range_resolution * w / params.image_extent[1],
    )
    step = 1.5 * focus_step(params)
    speeds = speed_bank(max_speed, step)
    folds = torch.arange(-max_fold, max_fold + 1)
    if detector is None:
        n_images = speeds.numel() + folds.numel() - 1
        detector = default_detector(res_px, pfa=pfa / n_images)
    bank = bank_detect(image, params, speeds, detector, folds=folds)
    noise = GHOST_NOISE * background(intensity(image))
    radius = max(1, math.ceil(2 * max(res_px)))
    peaks = (bank.mask & (bank.best == window_max(bank.best, radius)))[:, 0]
    found = []
    for b in range(image.shape[0]):
        pix = peaks[b].nonzero()
        value = bank.best[b, 0][peaks[b]]
        order = value.argsort(descending=True)
        pix, value = pix[order], value[order]
        speed, fold = (x[b, 0][pix[:, 0], pix[:, 1]] for x in (bank.speed, bank.fold))
        keep = ~smear_ghosts(
            pix,
            value,
            speed,
            fold,
            params,
            (h, w),
            speed_step=step,
            noise=float(noise[b]),
            window=window,
        )
        found.append([x[keep][:max_targets] for x in (pix, value, speed, fold)])
    return _pad(found, image.shape[0], image.device)


def _pad(found: list[list[Tensor]], b: int, device) -> Targets:
    """Per-scene ``[pixel, value, speed, fold]`` lists padded to one :class:`Targets`."""
    n = max([len(x[0]) for x in found], default=0)
    pixel = torch.full((b, n, 2), -1, dtype=torch.long, device=device)
    value = torch.zeros(b, n, device=device)
    speed = torch.zeros(b, n, dtype=torch.float64, device=device)
    fold = torch.zeros(b, n, dtype=torch.long, device=device)
    for i, (pix, val, v, k) in enumerate(found):
        m = len(pix)
        pixel[i, :m], value[i, :m], speed[i, :m], fold[i, :m] = pix, val, v, k
    return Targets(pixel, pixel[..., 0] >= 0, value, speed, fold)


def smear_ghosts(
    pixel: Tensor,
    value: Tensor,
    speed: Tensor,
    fold: Tensor,
    params: SpotlightParams,
    shape: tuple[int, int],
    *,
    source_value: Tensor | None = None,
    source_speed: Tensor | None = None,
    speed_step: float = 0.0,
    noise: float = 0.0,
    window: str = "hann",
    margin: float = GHOST_MARGIN,
) -> Tensor:
    """Peaks explained by the streak of a brighter peak in the bank image they were found in.

    A target of motion ``(v_j, k_j)`` and focused intensity ``I_j`` seen in the bank image
    of ``(v_i, k_i)`` is a streak through its position, at
    ``d = (-(k_j - k_i) lambda PRF / 2, 2 (v_j - v_i))`` m per second of slow time
    ``t in [-T/2, T/2]`` in ``(range, azimuth)``: the slow time ``t`` lands at ``t d``. There
    its intensity is ``I_j (w(t) tau / (T w_mean))^2`` (stationary phase), ``w`` the aperture
    taper and ``tau`` the coherent time of one position: ``1 / sqrt(alpha)`` for the azimuth
    chirp rate ``alpha = 4 V |v_j - v_i| / (lambda R0)`` of the speed error, ``2 rho_r / |d_r|``
    for a range walk through the range resolution ``rho_r``, ``(tau_a^-2 + tau_r^-2)^-1/2``
    for both. A weaker peak ``i`` within one resolution cell of the segment (in azimuth the
    cell a walk's dwell leaves, plus the bank's speed quantisation ``speed_step |t|``; one
    coherent time towards the centre) whose amplitude does not exceed the sum over brighter
    peaks of ``sqrt(margin)`` times their streak's (streaks may add coherently) plus
    ``sqrt(noise)`` is dropped. Peaks found in the same bank image as the brighter one's
    motion (``d = 0``) are never dropped: a weak stationary scatterer beside a bright
    stationary one is kept, however close its range cell, as long as it stands above the
    neighbour's streaks where it is.

    Args:
        pixel: long ``(n, 2)`` peaks sorted by decreasing ``value``.
        value: ``(n,)`` bank intensity at each peak.
        speed: ``(n,)`` speed (m/s) of the bank image each peak was found in.
        fold: ``(n,)`` fold of that image (also each peak's own fold as a source).
        params: the system.
        shape: ``(H, W)`` of the image (both axes are periodic).
        source_value: ``(n,)`` focused intensity of each peak as a streak source (default
            ``value``).
        source_speed: ``(n,)`` along-track speed of each peak as a source (default ``speed``).
        speed_step: uncertainty of the source speeds (m/s): the bank's speed spacing.
        noise: intensity a peak may owe to noise (e.g. a few times the mean background).
        window: the image-formation taper (``"hann"`` or ``"none"``).
        margin: streak intensity multiple still explained (ripples).

    Returns:
        bool ``(n,)``.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> p = SpotlightParams.from_system(image_size=(256, 512))
        >>> pix = torch.tensor([[10, 100], [10, 140], [10, 180]])  # one row, 11.7 m apart
        >>> v, k = torch.tensor([8.0, 0.0, 0.0]), torch.zeros(3)  # a fast mover, two still
        >>> smear_ghosts(pix, torch.tensor([1e4, 50.0, 5e3]), v, k, p, (256, 512)).tolist()
        [False, True, False]
    """
    h, w = shape
    spacing = torch.tensor(
        [params.image_extent[0] / h, params.image_extent[1] / w], dtype=torch.float64
    )
    period = spacing * torch.tensor([h, w], dtype=torch.float64)
    pos = pixel.cpu().double() * spacing
    delta = pos[:, None] - pos[None]  # (i, j, 2): peak i relative to peak j
    delta = delta - period * torch.floor(delta / period + 0.5)
    v_i, k = speed.cpu().double(), fold.cpu().double()
    v_j = v_i if source_speed is None else source_speed.cpu().double()
    drift = torch.stack(
        [-(k[None] - k[:, None]) * params.geometry.blind_speed, 2 * (v_j[None] - v_i[:, None])],
        -1,
    )
    level = streak_level(delta, drift, params, speed_step=speed_step, window=window)
    val = value.cpu().double()
    src = val if source_value is None else source_value.cpu().double()
    brighter = torch.ones_like(level, dtype=torch.bool).tril(-1)  # column j < row i
    # streaks of several brighter peaks may add coherently: sum their amplitudes
    streak = torch.where(brighter, (margin * src[None, :] * level).sqrt(), 0.0).sum(1)
    return ((level > 0) & brighter).any(1) & (val.sqrt() <= streak + math.sqrt(noise))
