"""Moving targets end to end: one detection, three tests (looks, focus, subpatches), one decision.

Single-channel SAR sees along-track motion to first order: the mover's azimuth FM rate is
off, so it is displaced between time sub-aperture looks (the look test) and focuses at a
non-zero speed (the focus test): two independent observables of the same velocity.
Radial (range) motion is, to first order, indistinguishable from a stationary target at a
displaced position (azimuth offset ``R v_r / V``) and is not found by either test; the
subpatch test (the seed's method) responds only to azimuth ambiguity (see
:mod:`torchsar.motion.theory`) and is reported, not used in the decision.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar._checks import check_complex, check_int, check_positive
from torchsar.cfar import Detection
from torchsar.motion.defocus import FocusTest, focus_test
from torchsar.motion.formation import polar_format
from torchsar.motion.looks import LookPlan, look_images, look_plan
from torchsar.motion.misregistration import LookTest, look_test
from torchsar.motion.params import SpotlightParams
from torchsar.motion.peaks import intensity
from torchsar.motion.strips import background, strips
from torchsar.motion.subpatch_test import subpatch_movers
from torchsar.motion.targets import detect_targets
from torchsar.motion.theory import wrap

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
        look: the look test (:class:`~torchsar.motion.misregistration.LookTest`).
        focus: the focus test (:class:`~torchsar.motion.defocus.FocusTest`).
        subpatch: bool ``(B, N)`` the subpatch decision of the associated subpatch track
            (False when not associated or not run).
        velocity: ``(B, N)`` along-track speed, inverse-variance mean of the two estimates.
        sigma: ``(B, N)`` its standard deviation.
        mover: bool ``(B, N)`` the combined decision: look test **and** focus test.
    """

    image: Tensor
    looks: Tensor
    plan: LookPlan
    pixel: Tensor
    position: Tensor
    valid: Tensor
    look: LookTest
    focus: FocusTest
    subpatch: Tensor
    velocity: Tensor
    sigma: Tensor
    mover: Tensor


def find_movers(
    phase_history: Tensor,
    params: SpotlightParams,
    *,
    looks: int = 2,
    overlap: float = 0.0,
    window: str = "hann",
    max_speed: float = 16.0,
    detector: Callable[[Tensor], Detection] | None = None,
    n_sigma: float = 5.0,
    min_sigma: float = 0.02,
    max_targets: int = 64,
    subpatch: bool = True,
) -> MoverReport:
    """Detect point targets and decide which move, by two independent tests.

    1. Full-aperture image; targets are CFAR peaks of its speed-bank intensity
       (:func:`~torchsar.motion.targets.detect_targets`), so smeared movers are found too.
    2. Focus test (:func:`~torchsar.motion.defocus.focus_test`): best-focusing speed.
    3. Look test (:func:`~torchsar.motion.misregistration.look_test`): displacement between
       ``looks`` time sub-apertures; looks are refocused for the focus speed when the focus
       test flags the target, else for 0.
    4. Combined decision: a mover when **both** tests exceed ``n_sigma`` (two independent
       signatures must agree); velocity = inverse-variance mean of the two estimates.
    5. With ``subpatch``, the subpatch test (:func:`~torchsar.motion.subpatch_test.subpatch_movers`)
       is run and its decision attached to the nearest target (within 3 m); it is not part of
       the decision (it flags azimuth ambiguity, not motion).

    Args:
        phase_history: complex ``(B, M, K)`` deramped on the scene centre.
        params: the system (the image's azimuth extent must be the sampled extent
            ``params.geometry.unambiguous_azimuth``, true whenever the scene is at least that wide).
        looks: number of looks (>= 2).
        overlap: fraction of a look shared with the next.
        window: image-formation taper.
        max_speed: largest along-track speed searched (m/s).
        detector: intensity -> :class:`~torchsar.cfar.Detection` (default CA-CFAR, pfa 1e-6).
        n_sigma: threshold of each test in standard deviations.
        min_sigma: floor (m/s) of each test's velocity standard deviation.
        max_targets: at most this many targets per scene.
        subpatch: also run the subpatch test.

    Returns:
        :class:`MoverReport`.

    Raises:
        InputTypeError, ShapeError, InputValueError, OptionError: bad input.

    Shape:
        ``(B, M, K)`` -> decision ``(B, N)``.

    Example:
        >>> import warnings; warnings.simplefilter("ignore")
        >>> from torchsar.motion import SpotlightParams
        >>> from torchsar.sar import add_noise, simulate_phase_history
        >>> p = SpotlightParams.from_system(image_size=(128, 512))
        >>> pos = torch.tensor([[[-20.0, -10.0], [15.0, 5.0], [0.0, -20.0], [30.0, 15.0]]])
        >>> vel = torch.zeros_like(pos); vel[0, 3, 1] = 2.0  # 2 m/s along track
        >>> g = add_noise(simulate_phase_history(pos, p.geometry, velocities=vel), std=0.3, seed=0)
        >>> r = find_movers(g, p, subpatch=False)
        >>> r.mover.tolist(), round(float(r.velocity[r.mover]), 1)
        ([[False, False, False, True]], 2.0)
    """
    check_complex(phase_history, "phase_history", ndim=3)
    check_int(looks, "looks", minimum=2)
    check_positive(n_sigma, "n_sigma")
    plan = look_plan(params, looks=looks, overlap=overlap)
    image = polar_format(phase_history, params, window=window)
    look_imgs = look_images(phase_history, params, looks=looks, overlap=overlap, window=window)
    pixel, valid = detect_targets(
        image, params, max_speed=max_speed, detector=detector, max_targets=max_targets
    )
    focus = _focus(image, params, pixel, valid, max_speed, n_sigma, min_sigma)
    speed = torch.where(focus.mover, focus.velocity, torch.zeros_like(focus.velocity))
    look = look_test(
        look_imgs, plan, params, pixel=pixel, valid=valid, speed=speed,
        background=background(intensity(look_imgs)), n_sigma=n_sigma, min_sigma=min_sigma,
    )  # fmt: skip
    position = _positions(pixel, valid, params, image.shape[-2:])
    sub = _subpatch(phase_history, params, position, valid, window, n_sigma) if subpatch else None
    velocity, sigma = _combine(look, focus)
    return MoverReport(
        image, look_imgs, plan, pixel, position, valid, look, focus,
        torch.zeros_like(valid) if sub is None else sub,
        velocity, sigma, look.mover & focus.mover,
    )  # fmt: skip


def _focus(image, params, pixel, valid, max_speed, n_sigma, min_sigma) -> FocusTest:
    """Focus test on the full-aperture strips around each target."""
    b, n = valid.shape
    half = 1  # along-track motion stays in its range cell; the peak row +- 1
    idx = torch.arange(b, device=pixel.device)[:, None].expand(b, n).reshape(-1)
    rows = pixel[..., 0].clamp(min=0).reshape(-1)
    x = strips(image[:, None], idx, rows, half)[:, 0].reshape(b, n, 2 * half + 1, image.shape[-1])
    return focus_test(
        x, params, column=pixel[..., 1].clamp(min=0), valid=valid,
        background=background(intensity(image)), max_speed=max_speed,
        n_sigma=n_sigma, min_sigma=min_sigma,
    )  # fmt: skip


def _positions(pixel: Tensor, valid: Tensor, params: SpotlightParams, shape) -> Tensor:
    """Image position ``(range, azimuth)`` in m of each target pixel (NaN for padding)."""
    ext = params.image_extent
    spacing = torch.tensor([ext[0] / shape[0], ext[1] / shape[1]], dtype=torch.float64)
    centre = torch.tensor([shape[0] // 2, shape[1] // 2], dtype=torch.float64)
    pos = (pixel.cpu().double() - centre) * spacing
    return torch.where(valid.cpu()[..., None], pos, torch.nan)


def _combine(look: LookTest, focus: FocusTest) -> tuple[Tensor, Tensor]:
    """Inverse-variance mean of the look and focus velocities and its sigma."""
    wl, wf = look.sigma.pow(-2), focus.sigma.pow(-2).to(look.sigma)
    velocity = (wl * look.velocity + wf * focus.velocity.to(look.velocity)) / (wl + wf)
    return velocity, (wl + wf).rsqrt()


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
