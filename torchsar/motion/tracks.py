"""Associate point targets across subpatch images and measure their sub-pixel displacements.

Targets are taken from the reference subpatch image (``p = 0``). In image ``p`` a stationary
target is expected at its reference position plus the nominal centre offset ``c_0 - c_p``
(wrapped: the images are periodic with the sampled extent); each reference target is paired
with one detection of image ``p`` by minimum total distance (Hungarian assignment) within a
gate. The pairing is refined to sub-pixel precision by cross-correlating amplitude chips
around the two detections (:func:`~torchsar.motion.shift.estimate_shift`).

The *excess displacement* of target ``i`` in image ``p`` is its measured displacement minus
``c_0 - c_p`` (zero for a stationary target up to wavefront-curvature distortion). With
``correct_distortion`` the detections are first mapped back to scene positions through the
planar-model distortion (:func:`~torchsar.motion.theory.scene_positions`), so a stationary
target's excess displacement is zero up to noise.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
from scipy.optimize import linear_sum_assignment
from torch import Tensor

from torchsar._checks import check_complex, check_int, check_positive
from torchsar.cfar import Detection
from torchsar.motion.params import SpotlightParams
from torchsar.motion.peaks import default_detector, detect_peaks
from torchsar.motion.shift import estimate_shift
from torchsar.motion.theory import scene_positions, wrap

__all__ = ["Tracks", "associate", "measure_displacements"]


@dataclass(frozen=True)
class Tracks:
    """Targets found in the reference subpatch image and followed through all images.

    Padded to the largest target count of the batch; padding rows have ``valid`` all False.

    Attributes:
        pixel: long ``(B, N, P, 2)`` detection pixel per image (-1 where not associated).
        position: float64 ``(B, N, P, 2)`` sub-pixel image position relative to each centre, m.
        excess: float64 ``(B, N, P, 2)`` displacement beyond the nominal ``c_0 - c_p``, m.
        corrected: float64 ``(B, N, P, 2)`` the same after planar distortion correction, m.
        snr: float64 ``(B, N)`` peak-to-mean-background intensity ratio in image 0.
        valid: bool ``(B, N, P)`` target present and associated in image ``p``.
    """

    pixel: Tensor
    position: Tensor
    excess: Tensor
    corrected: Tensor
    snr: Tensor
    valid: Tensor


def associate(
    reference: Tensor, candidates: Tensor, offset: Tensor, period: Tensor, gate: float
) -> Tensor:
    """Index into ``candidates`` for each reference point (-1 if none within ``gate``).

    Minimises the total periodic distance between ``reference + offset`` and the assigned
    candidates (Hungarian algorithm, :func:`scipy.optimize.linear_sum_assignment`).

    Args:
        reference: ``(n, 2)`` points.
        candidates: ``(m, 2)`` points.
        offset: ``(2,)`` expected displacement.
        period: ``(2,)`` periodicity of the coordinates (``inf`` for none).
        gate: maximum distance of a pair.

    Returns:
        long ``(n,)``.

    Examples:
        >>> ref = torch.tensor([[0.0, 0.0], [10.0, 0.0]])
        >>> cand = torch.tensor([[11.0, 1.0], [1.0, 1.0], [50.0, 50.0]])
        >>> associate(ref, cand, torch.zeros(2), torch.tensor([1e9, 1e9]), 3.0).tolist()
        [1, 0]
    """
    out = torch.full((reference.shape[0],), -1, dtype=torch.long)
    if reference.shape[0] == 0 or candidates.shape[0] == 0:
        return out
    d = wrap(candidates[None].double() - (reference[:, None] + offset).double(), period.double())
    cost = d.norm(dim=-1)
    rows, cols = linear_sum_assignment(torch.where(cost <= gate, cost, 1e12).numpy())
    keep = cost[rows, cols] <= gate
    out[torch.as_tensor(rows)[keep]] = torch.as_tensor(cols, dtype=torch.long)[keep]
    return out


def _grid(params: SpotlightParams, shape: tuple[int, int]) -> tuple[Tensor, Tensor, Tensor]:
    """Pixel spacing, centre pixel and image period (m) for images of ``shape``."""
    ext = params.image_extent
    spacing = torch.tensor([ext[0] / shape[0], ext[1] / shape[1]], dtype=torch.float64)
    centre = torch.tensor([shape[0] // 2, shape[1] // 2], dtype=torch.float64)
    period = torch.tensor(
        [params.geometry.unambiguous_range, params.geometry.unambiguous_azimuth],
        dtype=torch.float64,
    )
    return spacing, centre, period


def _pair(
    peaks: list[Tensor],
    centers: Tensor,
    spacing: Tensor,
    centre: Tensor,
    period: Tensor,
    gate: float,
) -> Tensor:
    """Pixels ``(n, P, 2)`` (-1 = missing) of the reference peaks followed through every image."""
    ref = peaks[0]
    pix = torch.full((ref.shape[0], len(peaks), 2), -1, dtype=torch.long)
    pix[:, 0] = ref
    ref_m = (ref.double() - centre) * spacing
    for p in range(1, len(peaks)):
        cand_m = (peaks[p].double() - centre) * spacing
        idx = associate(ref_m, cand_m, centers[0] - centers[p], period, gate)
        ok = idx >= 0
        pix[ok, p] = peaks[p][idx[ok]]
    return pix


def _chips(amplitude: Tensor, b: Tensor, p: Tensor, pix: Tensor, size: int) -> Tensor:
    """``(T, size, size)`` chips of ``amplitude (B, P, H, W)`` around ``pix (T, 2)``, circular."""
    half = size // 2
    h, w = amplitude.shape[-2:]
    k = torch.arange(size) - half
    rows = (pix[:, 0, None] + k) % h
    cols = (pix[:, 1, None] + k) % w
    return amplitude[b[:, None, None], p[:, None, None], rows[:, :, None], cols[:, None, :]]


def _peak_lists(peaks: Tensor, intensity: Tensor, max_targets: int) -> list[list[Tensor]]:
    """Per batch and image, peak pixels ``(n, 2)`` sorted by decreasing intensity."""
    out = []
    for b in range(peaks.shape[0]):
        row = []
        for p in range(peaks.shape[1]):
            pix = peaks[b, p].nonzero().cpu()
            order = intensity[b, p][peaks[b, p]].cpu().argsort(descending=True)
            row.append(pix[order][: max_targets if p == 0 else 4 * max_targets])
        out.append(row)
    return out


def measure_displacements(
    images: Tensor,
    params: SpotlightParams,
    centers: Tensor,
    *,
    detector: Callable[[Tensor], Detection] | None = None,
    radius: int | None = None,
    chip: int = 32,
    upsample: int = 20,
    gate: float = 15.0,
    max_targets: int = 64,
    window: str = "hann",
) -> Tracks:
    """Detect targets in every subpatch image, associate them and measure their displacements.

    Args:
        images: complex ``(B, P, H, W)`` subpatch images
            (:func:`~torchsar.motion.subpatch.subpatch_images`).
        params: the system the images were formed with.
        centers: ``(P, 2)`` image centres in m (same order as ``images``).
        detector: intensity ``(B, C, H, W)`` -> :class:`~torchsar.cfar.Detection`; default
            :func:`~torchsar.motion.peaks.default_detector` sized to the resolution.
        radius: peak suppression half-width in pixels; default two resolution cells.
        chip: side of the square amplitude chips cross-correlated (pixels).
        upsample: sub-pixel refinement factor of :func:`~torchsar.motion.shift.estimate_shift`.
        gate: association gate in m (must exceed the largest mover displacement expected).
        max_targets: at most this many (brightest) targets are followed per scene.
        window: the image-formation taper (for the distortion correction).

    Returns:
        :class:`Tracks`.

    Raises:
        InputTypeError, ShapeError, InputValueError, OptionError: bad input.

    Shape:
        ``(B, P, H, W)`` -> tracks ``(B, N, P, ...)``.
    """
    check_complex(images, "images", ndim=4)
    chip = check_int(chip, "chip", minimum=4)
    gate = check_positive(gate, "gate")
    h, w = images.shape[-2:]
    spacing, centre, period = _grid(params, (h, w))
    res_px = (
        params.geometry.range_resolution / float(spacing[0]),
        params.geometry.cross_range_resolution / float(spacing[1]),
    )
    detector = default_detector(res_px) if detector is None else detector
    radius = max(1, math.ceil(2 * max(res_px))) if radius is None else radius
    intensity = images.abs().square()
    peaks = detect_peaks(intensity, detector=detector, radius=radius)
    lists = _peak_lists(peaks, intensity, max_targets)
    c = centers.to(torch.float64).cpu()
    pairs = [_pair(row, c, spacing, centre, period, gate) for row in lists]
    n = max([x.shape[0] for x in pairs], default=0)
    pix = torch.full((len(pairs), n, images.shape[1], 2), -1, dtype=torch.long)
    for b, x in enumerate(pairs):
        pix[b, : x.shape[0]] = x
    return _measure(
        images.abs(), intensity, pix, params, c, spacing, centre, period, chip, upsample, window
    )


def _measure(
    amplitude: Tensor,
    intensity: Tensor,
    pix: Tensor,
    params: SpotlightParams,
    centers: Tensor,
    spacing: Tensor,
    centre: Tensor,
    period: Tensor,
    chip: int,
    upsample: int,
    window: str,
) -> Tracks:
    """Sub-pixel positions, excess displacements and SNR of paired pixels ``pix (B, N, P, 2)``."""
    valid = (pix >= 0).all(-1)
    b, i, p = valid.nonzero(as_tuple=True)
    dev = amplitude.device
    mov = _chips(amplitude, b.to(dev), p.to(dev), pix[b, i, p].to(dev), chip)
    ref = _chips(amplitude, b.to(dev), torch.zeros_like(p).to(dev), pix[b, i, 0].to(dev), chip)
    shift = torch.zeros((*valid.shape, 2), dtype=torch.float64)
    shift[b, i, p] = estimate_shift(ref, mov, upsample=upsample).double().cpu()
    nan = torch.tensor(float("nan"), dtype=torch.float64)
    position = torch.where(valid[..., None], (pix.double() - shift - centre) * spacing, nan)
    offset = centers[0] - centers  # (P, 2) nominal displacement
    excess = wrap(position - position[:, :, :1] - offset, period)
    scene = scene_positions(torch.nan_to_num(position), params, centers, window=window)
    corrected = torch.where(valid[..., None], wrap(scene - scene[:, :, :1], period), nan)
    snr = _snr(intensity[:, 0].cpu(), pix[:, :, 0])
    return Tracks(pix, position, excess, corrected, snr, valid)


def _snr(intensity: Tensor, pix: Tensor) -> Tensor:
    """Peak intensity over the mean background (median / ln 2, robust to the few targets)."""
    bg = intensity.flatten(1).double().median(dim=1).values / math.log(2)
    b = torch.arange(pix.shape[0])[:, None].expand(pix.shape[:2])
    peak = intensity[b, pix[..., 0].clamp(min=0), pix[..., 1].clamp(min=0)].double()
    return torch.where(pix[..., 0] >= 0, peak / bg[:, None].clamp(min=1e-300), torch.nan)
