"""Moving targets end to end: one detection, the look, focus and subpatch tests, one verdict.

Single-channel SAR sees along-track motion to first order: the mover's azimuth FM rate is
off, so it is displaced in azimuth between time sub-aperture looks (the look test) and
focuses at a non-zero speed (the focus test): two independent observables of the same
velocity, which must agree. Radial motion is, to first order, a stationary target at a
displaced azimuth (``R v_r / V``); when that displacement leaves the sampled azimuth extent
the target is Doppler-folded and keeps a residual range walk of ``k lambda PRF / 2`` per
second (:mod:`torchsar.motion.folds`): the looks see it walk in range and the motion bank
compacts it at fold ``k``; two observables of the same fold. An unfolded radial mover shows
neither. The subpatch test (the seed's method) responds only to azimuth ambiguity (see
:mod:`torchsar.motion.theory`) and is reported, not used in the verdict.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar._checks import check_complex, check_int, check_positive
from torchsar.cfar import Detection
from torchsar.motion.defocus import FocusTest, focus_test
from torchsar.motion.focus import focus_step
from torchsar.motion.formation import polar_format
from torchsar.motion.looks import LookPlan, look_images, look_plan
from torchsar.motion.misregistration import LookTest, look_test
from torchsar.motion.params import SpotlightParams
from torchsar.motion.peaks import intensity
from torchsar.motion.selection import repack
from torchsar.motion.streaks import look_interference
from torchsar.motion.strips import background, strips
from torchsar.motion.subpatch_movers import subpatch_movers
from torchsar.motion.targets import GHOST_NOISE, Targets, detect_targets, smear_ghosts
from torchsar.motion.theory import wrap
from torchsar.motion.verdict import Verdict, verdict

__all__ = ["MoverReport", "find_movers"]


@dataclass(frozen=True)
class MoverReport:
    """Output of :func:`find_movers`; per-target fields are ``(B, N)`` (padding: invalid).

    Attributes:
        image: complex ``(B, H, W)`` full-aperture image.
        looks: complex ``(B, K, H, W)`` look images; ``plan`` their pulses and times.
        plan: :class:`~torchsar.motion.looks.LookPlan`.
        pixel: long ``(B, N, 2)`` target pixel in ``image`` (-1 for padding).
        position: float64 ``(B, N, 2)`` ``(range, azimuth)`` image position in m.
        valid: bool ``(B, N)``.
        targets: the detection (:class:`~torchsar.motion.targets.Targets`: bank speed and
            fold of each target).
        look: the look test (:class:`~torchsar.motion.misregistration.LookTest`), azimuth
            and range.
        focus: the focus test (:class:`~torchsar.motion.defocus.FocusTest`).
        subpatch: bool ``(B, N)`` the subpatch decision of the associated subpatch track
            (False when not associated or not run).
        velocity: ``(B, N)`` along-track speed, inverse-variance mean of the two estimates.
        sigma: ``(B, N)`` its standard deviation.
        mover: bool ``(B, N)`` an along-track mover: look and focus tests significant and in
            agreement, no range walk (:mod:`~torchsar.motion.verdict`).
        radial: bool ``(B, N)`` a Doppler-folded radial mover: range walk between looks
            confirmed by the bank's fold. Never both ``mover`` and ``radial``.
        fold: long ``(B, N)`` its Doppler fold ``k`` (0 when not radial).
        radial_speed: float64 ``(B, N, 2)`` lowest and highest radial speed (m/s) that fold
            allows for a target within the scene (NaN when not radial).
        conflict: bool ``(B, N)`` significant tests that disagree (neither mover nor radial).
        verdict: the full :class:`~torchsar.motion.verdict.Verdict` (with ``discrepancy``).
    """

    image: Tensor
    looks: Tensor
    plan: LookPlan
    pixel: Tensor
    position: Tensor
    valid: Tensor
    targets: Targets
    look: LookTest
    focus: FocusTest
    subpatch: Tensor
    verdict: Verdict

    @property
    def velocity(self) -> Tensor:
        return self.verdict.velocity

    @property
    def sigma(self) -> Tensor:
        return self.verdict.sigma

    @property
    def mover(self) -> Tensor:
        return self.verdict.mover

    @property
    def radial(self) -> Tensor:
        return self.verdict.radial

    @property
    def fold(self) -> Tensor:
        return self.verdict.fold

    @property
    def radial_speed(self) -> Tensor:
        return self.verdict.radial_speed

    @property
    def conflict(self) -> Tensor:
        return self.verdict.conflict


def find_movers(
    phase_history: Tensor,
    params: SpotlightParams,
    *,
    looks: int = 2,
    overlap: float = 0.0,
    window: str = "hann",
    max_speed: float = 16.0,
    max_fold: int = 2,
    detector: Callable[[Tensor], Detection] | None = None,
    n_sigma: float = 5.0,
    agree_sigma: float = 4.0,
    min_sigma: float = 0.0,
    max_targets: int = 64,
    subpatch: bool = True,
) -> MoverReport:
    """Detect point targets and decide which move along track and which are folded radially.

    1. Full-aperture image; targets are CFAR peaks of its motion bank (refocused for
       along-track speeds, unwalked for Doppler folds;
       :func:`~torchsar.motion.targets.detect_targets`), so smeared movers and walking
       radial movers are found once each.
    2. Focus test (:func:`~torchsar.motion.defocus.focus_test`): best-focusing speed, each
       target at its own slant range.
    3. Look test (:func:`~torchsar.motion.misregistration.look_test`): azimuth and range
       displacement between ``looks`` time sub-apertures; looks are refocused for the focus
       speed when the focus test flags the target and the bank saw no fold (else 0) and
       unwalked for the bank's fold.
    4. Verdict (:func:`~torchsar.motion.verdict.verdict`): an along-track mover when the
       look and focus tests are both significant and agree and the target does not walk in
       range; a radial (folded) mover when the range walk is significant and matches the
       bank's fold; a conflict when significant tests disagree. Velocity = inverse-variance
       mean of the two estimates.
    5. With ``subpatch``, the subpatch test
       (:func:`~torchsar.motion.subpatch_movers.subpatch_movers`) is run and its decision
       attached to the nearest target (within 3 m); it is not part of the verdict (it
       flags azimuth ambiguity, not motion).

    Args:
        phase_history: complex ``(B, M, K)`` deramped on the scene centre.
        params: the system (the image's azimuth extent must be the sampled extent
            ``params.geometry.unambiguous_azimuth``, true whenever the scene is at least that wide).
        looks: number of looks (>= 2).
        overlap: fraction of a look shared with the next.
        window: image-formation taper.
        max_speed: largest along-track speed searched (m/s).
        max_fold: largest Doppler fold in the motion bank (0: none; folds up to
            ``max_fold + 1`` are still measured by the looks). The walk needs range sampled
            at the range resolution: with coarser range pixels the bank has no folds and no
            target is flagged radial.
        detector: intensity -> :class:`~torchsar.cfar.Detection` (default CA-CFAR, pfa 1e-6).
        n_sigma: threshold of each test in standard deviations.
        agree_sigma: largest disagreement of two tests of one motion, in combined sigmas.
        min_sigma: optional floor (m/s) of each test's velocity standard deviation (none by
            default: the sigmas are measured to cover the errors).
        max_targets: at most this many targets per scene.
        subpatch: also run the subpatch test.

    Returns:
        :class:`MoverReport`.

    Raises:
        InputTypeError, ShapeError, InputValueError, OptionError: bad input.

    Shape:
        ``(B, M, K)`` -> decision ``(B, N)``.

    Examples:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> from torchsar.motion import SpotlightParams
        >>> from torchsar.sar import add_noise, image_noise_std, simulate_phase_history
        >>> p = SpotlightParams.from_system(image_size=(256, 512))  # 0.7 m range pixels
        >>> pos = torch.tensor([[[-20.0, -10.0], [15.0, 5.0], [0.0, -20.0], [30.0, 15.0],
        ...                      [-40.0, 30.0]]])
        >>> vel = torch.zeros_like(pos); vel[0, 3, 1] = 2.0  # 2 m/s along track
        >>> vel[0, 4, 0] = 3.0  # 3 m/s in range: shown 150 m off, folded once
        >>> g = simulate_phase_history(pos, p.geometry, velocities=vel)
        >>> r = find_movers(add_noise(g, std=image_noise_std(p.geometry, 30.0)), p, subpatch=False)
        >>> i = r.mover.nonzero()[0, 1]
        >>> round(float(r.velocity[0, i]), 1), r.radial.sum().item(), r.fold[r.radial].tolist()
        (2.0, 1, [-1])
    """
    check_complex(phase_history, "phase_history", ndim=3)
    check_int(looks, "looks", minimum=2)
    max_fold = check_int(max_fold, "max_fold", minimum=0)
    check_positive(n_sigma, "n_sigma")
    check_positive(agree_sigma, "agree_sigma")
    plan = look_plan(params, looks=looks, overlap=overlap)
    walkable = params.pixel_spacing[0] <= params.geometry.range_resolution
    max_fold = max_fold if walkable else 0  # range undersampled: unwalking would alias
    image = polar_format(phase_history, params, window=window)
    look_imgs = look_images(phase_history, params, looks=looks, overlap=overlap, window=window)
    targets = detect_targets(
        image,
        params,
        max_speed=max_speed,
        max_fold=max_fold,
        detector=detector,
        max_targets=max_targets,
        window=window,
    )
    bg = background(intensity(image))
    focus = _focus(image, params, targets, bg, max_speed, n_sigma, min_sigma)
    keep = _not_ghosts(targets, focus, params, image.shape[-2:], bg, window)
    targets, focus = repack(targets, keep), repack(focus, keep)
    pixel, valid = targets.pixel, targets.valid
    position = _positions(pixel, valid, params, image.shape[-2:])
    along = focus.mover & (targets.fold == 0).to(focus.mover.device)  # folded: no along-track
    speed = torch.where(along, focus.velocity, torch.zeros_like(focus.velocity))
    brightness = torch.maximum(focus.snr * bg.to(focus.snr)[:, None], targets.value.to(focus.snr))
    crowding = look_interference(
        position, speed, targets.fold, brightness, valid, plan, params, window=window
    )
    look = look_test(
        look_imgs,
        plan,
        params,
        pixel=pixel,
        valid=valid,
        speed=speed,
        fold=targets.fold,
        max_fold=max_fold,
        interference=crowding,
        background=background(intensity(look_imgs)),
        n_sigma=n_sigma,
        min_sigma=min_sigma,
    )
    decided = verdict(
        look,
        focus,
        targets.fold,
        position,
        params,
        n_sigma=n_sigma,
        agree_sigma=agree_sigma,
        max_fold=max_fold,
        walk=walkable,
    )
    sub = _subpatch(phase_history, params, position, valid, window, n_sigma) if subpatch else None
    return MoverReport(
        image,
        look_imgs,
        plan,
        pixel,
        position,
        valid,
        targets,
        look,
        focus,
        torch.zeros_like(valid) if sub is None else sub,
        decided,
    )


def _focus(image, params, targets: Targets, bg, max_speed, n_sigma, min_sigma) -> FocusTest:
    """Focus test on the full-aperture strips around each target, at its own range; the
    stationary pattern from the targets the bank found still (speed 0, fold 0)."""
    pixel, valid = targets.pixel, targets.valid
    b, n = valid.shape
    half = 1  # along-track motion stays in its range cell; the peak row +- 1
    idx = torch.arange(b, device=pixel.device)[:, None].expand(b, n).reshape(-1)
    rows = pixel[..., 0].clamp(min=0).reshape(-1)
    x = strips(image[:, None], idx, rows, half)[:, 0].reshape(b, n, 2 * half + 1, image.shape[-1])
    ranges = (pixel[..., 0].double() - image.shape[-2] // 2) * params.pixel_spacing[0]
    return focus_test(
        x,
        params,
        column=pixel[..., 1].clamp(min=0),
        valid=valid,
        background=bg,
        max_speed=max_speed,
        n_sigma=n_sigma,
        min_sigma=min_sigma,
        ranges=ranges,
        reference=(targets.speed == 0) & (targets.fold == 0),
    )


def _not_ghosts(targets: Targets, focus: FocusTest, params, shape, bg, window) -> Tensor:
    """bool ``(B, N)``: targets not explained by the streak of a brighter one, each source at
    its refined motion (the focus test's speed where it is significant and the bank saw no
    fold, else the bank's) and focused intensity (the larger of the focus peak and the bank
    value)."""
    along = focus.mover & (targets.fold == 0).to(focus.mover.device)
    speed = torch.where(along, focus.velocity, targets.speed.to(focus.velocity))
    bank_value = targets.value.double().to(focus.snr)
    peak = (focus.snr * bg.to(focus.snr)[:, None]).nan_to_num()
    source = torch.maximum(peak, bank_value)
    keep = targets.valid.clone()
    for b in range(keep.shape[0]):
        n = int(targets.valid[b].sum())
        ghost = smear_ghosts(
            targets.pixel[b, :n],
            bank_value[b, :n],
            targets.speed[b, :n],
            targets.fold[b, :n],
            params,
            shape,
            source_value=source[b, :n],
            source_speed=speed[b, :n],
            noise=GHOST_NOISE * float(bg[b]),
            window=window,
            speed_step=focus_step(params) / 2,
        )
        keep[b, :n] &= ~ghost.to(keep.device)
    return keep


def _positions(pixel: Tensor, valid: Tensor, params: SpotlightParams, shape) -> Tensor:
    """Image position ``(range, azimuth)`` in m of each target pixel (NaN for padding)."""
    ext = params.image_extent
    spacing = torch.tensor([ext[0] / shape[0], ext[1] / shape[1]], dtype=torch.float64)
    centre = torch.tensor([shape[0] // 2, shape[1] // 2], dtype=torch.float64)
    pos = (pixel.cpu().double() - centre) * spacing
    return torch.where(valid.cpu()[..., None], pos, torch.nan)


def _subpatch(g, params, position, valid, window, n_sigma) -> Tensor:
    """Subpatch decision of the subpatch track nearest each target (3 m gate)."""
    result = subpatch_movers(g, params, window=window, n_sigma=n_sigma)
    tracks = result.tracks
    period = torch.tensor([params.geometry.unambiguous_range, params.geometry.unambiguous_azimuth])
    track_pos = tracks.position[:, :, 0] + result.centers[0].double()  # (B, N', 2)
    d = wrap(position[:, :, None] - track_pos[:, None], period.double()).norm(dim=-1)
    d = torch.where(tracks.valid[:, None, :, 0], d, torch.inf).nan_to_num(nan=torch.inf)
    if d.shape[-1] == 0:
        return torch.zeros_like(valid)
    dist, nearest = d.min(-1)
    flagged = torch.gather(result.decision.mover, 1, nearest)
    return (valid.cpu() & (dist <= 3.0) & flagged).to(valid.device)
