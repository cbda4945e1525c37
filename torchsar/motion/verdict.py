"""The mover verdict: what the look test, the focus test and the motion bank say together.

Rules (each test's sigma is its measured standard deviation, see :mod:`.misregistration`
and :mod:`.defocus`):

- **walking**: the target is seen in every look, and the look test's range walk exceeds
  ``n_sigma`` of its sigma and is at least half a fold's (``|k_look| >= 0.5``,
  ``k_look = -walk / (lambda PRF / 2)``). Along-track motion and stationary targets do not
  walk (an along-track mover's residual is a few hundredths of a fold).
- **radial** (a Doppler-folded radial mover): walking, ``k_look`` within
  ``agree_sigma`` sigmas plus :data:`FOLD_TOLERANCE` of an integer ``k``, and the motion
  bank found the target brightest at that fold (or, beyond the bank's ``max_fold``, at its
  last fold of the same sign): two independent views of the same fold.
- **mover** (along track): the look and the focus test each exceed ``n_sigma``, their
  speeds agree within ``agree_sigma`` combined sigmas
  (``|v_look - v_focus| <= agree_sigma sqrt(s_look^2 + s_focus^2)``), and the target does not
  walk. A target is never both mover and radial.
- **conflict**: two significant signatures that do not tell one story: look and focus
  both significant but disagreeing, or a walk the bank's fold does not confirm (not a
  radial mover: a radial mover's walk corrupts the along-track tests, which are then not
  read). Such a target is neither mover nor radial, and is reported.

Images whose range pixels are coarser than the range resolution cannot measure the walk:
there nothing walks and nothing is radial.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from torchsar.motion.defocus import FocusTest
from torchsar.motion.folds import radial_speed_interval
from torchsar.motion.misregistration import LookTest
from torchsar.motion.params import SpotlightParams

__all__ = ["FOLD_TOLERANCE", "Verdict", "verdict"]

# |k_look - k| allowed beyond the noise (model error of the walk): measured up to 0.05 of a
# fold on the ladder's folded movers (1 to 5 folds, 30 dB) and the random scenes.
FOLD_TOLERANCE = 0.15


@dataclass(frozen=True)
class Verdict:
    """Output of :func:`verdict`; all ``(B, N)`` (``radial_speed`` ``(B, N, 2)``).

    Attributes:
        velocity: along-track speed, inverse-variance mean of the look and focus estimates.
        sigma: its standard deviation.
        discrepancy: ``|v_look - v_focus| / sqrt(s_look^2 + s_focus^2)``.
        mover: bool, an along-track mover.
        radial: bool, a Doppler-folded radial mover.
        fold: long, its fold ``k`` (0 when not radial).
        radial_speed: float64 lowest and highest radial speed the fold allows for a target
            within the scene (m/s; NaN when not radial).
        conflict: bool, significant tests that disagree.
    """

    velocity: Tensor
    sigma: Tensor
    discrepancy: Tensor
    mover: Tensor
    radial: Tensor
    fold: Tensor
    radial_speed: Tensor
    conflict: Tensor


def _fold(look: LookTest, bank_fold: Tensor, params, n_sigma, agree_sigma, max_fold):
    """``(walking, radial, fold)`` from the range walk and the bank's fold."""
    b = params.geometry.blind_speed
    k_look, sigma_k = -look.walk / b, look.walk_sigma / b
    significant = look.walk.abs() > n_sigma * look.walk_sigma
    walking = look.seen & significant & (k_look.abs() >= 0.5)
    k = torch.round(k_look).nan_to_num().long()
    integer = (k_look - k).abs() <= agree_sigma * sigma_k + FOLD_TOLERANCE
    bank = bank_fold.to(k)
    beyond = (k.abs() > max_fold) & (bank == k.sign() * max_fold)
    radial = walking & (k != 0) & integer & ((bank == k) | beyond)
    return walking, radial, torch.where(radial, k, torch.zeros_like(k))


def verdict(
    look: LookTest,
    focus: FocusTest,
    bank_fold: Tensor,
    position: Tensor,
    params: SpotlightParams,
    *,
    n_sigma: float = 5.0,
    agree_sigma: float = 4.0,
    max_fold: int = 0,
    walk: bool = True,
) -> Verdict:
    """Combine the tests by the rules of the module docstring.

    Args:
        look: the look test (azimuth and range).
        focus: the focus test.
        bank_fold: long ``(B, N)`` fold of the bank image where each target is brightest.
        position: ``(B, N, 2)`` image position of each target (m).
        params: the system.
        n_sigma: significance threshold of each test.
        agree_sigma: agreement threshold in combined sigmas.
        max_fold: the bank's largest fold.
        walk: whether the range walk is measurable (images sampling range at the range
            resolution); without it no target walks and none is radial.

    Returns:
        :class:`Verdict`.
    """
    walking, radial, fold = _fold(look, bank_fold, params, n_sigma, agree_sigma, max_fold)
    walking, radial = walking & walk, radial & walk
    fold = torch.where(radial, fold, torch.zeros_like(fold))
    v_f, s_f = focus.velocity.to(look.velocity), focus.sigma.to(look.sigma)
    wl, wf = look.sigma.pow(-2), s_f.pow(-2)
    velocity = (wl * look.velocity + wf * v_f) / (wl + wf)
    discrepancy = (look.velocity - v_f).abs() / look.sigma.hypot(s_f)
    agree = discrepancy <= agree_sigma
    both = look.mover & focus.mover.to(look.mover.device)
    mover = both & agree & ~walking
    conflict = ((both & ~agree) | walking) & ~radial
    interval = radial_speed_interval(fold, position.to(look.walk.device), params)
    interval = torch.where(radial[..., None], interval, torch.nan)
    return Verdict(
        velocity, (wl + wf).rsqrt(), discrepancy, mover, radial, fold, interval, conflict
    )
