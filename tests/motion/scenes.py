"""Seeded random mover scenes for the motion tests, built only through the public API.

Each scene of the Table-1 system holds 6-10 stationary point scatterers, 1-2 along-track
movers (0.5-13 m/s, either sign) and, in every other scene, a range mover whose Doppler is
folded ``|k| = 1..2`` times or not at all; positions are uniform over +-75 m range x +-60 m
azimuth (an along-track mover's apparent track ``x +- v T`` within +-70 m: one that leaves
the 150 m sampled extent during the aperture is folded for part of it and is neither an
along-track nor a radial mover, tested on its own), amplitudes span 15 dB (``0..15`` dB above the unit point, random phase), and the
noise gives a unit point ``snr_db`` of image peak SNR
(:func:`~torchsar.sar.image_noise_std`). Scene ``i`` of seed ``s`` depends only on
``(s, i)``, never on the batch. Targets are kept 8 m apart in the image (their apparent,
folded position) and in each of two looks: a weak target closer to a bright one is masked
by the default CA-CFAR's training window (7 m in range), a detector matter, not a motion one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch
from torch import Tensor

from torchsar.motion import SpotlightParams, look_displacement, planar_image_positions, wrap
from torchsar.sar import add_noise, image_noise_std, simulate_phase_history
from torchsar.simulate import image_seed

STILL, ALONG, RADIAL = 0, 1, 2
RANGE_HALF, AZIMUTH_HALF = 75.0, 60.0
MIN_SEPARATION = 8.0  # m between apparent positions: beyond the default CFAR window
FOLD_MARGIN = 0.4  # apparent azimuth within +-0.4 periods of its fold's centre
EDGE = 70.0  # m: an along-track mover's apparent track (x +- v T) stays this far in


@dataclass(frozen=True)
class Scene:
    """One scene's truth: ``(N, 2)`` positions and velocities ``(range, azimuth)``, amplitudes,
    kind (STILL / ALONG / RADIAL), Doppler fold and apparent image position (m)."""

    position: Tensor
    velocity: Tensor
    amplitude: Tensor
    kind: Tensor
    fold: Tensor
    image: Tensor


def _uniform(gen: torch.Generator, n: int, lo: float, hi: float) -> Tensor:
    return lo + (hi - lo) * torch.rand(n, generator=gen, dtype=torch.float64)


def _sign(gen: torch.Generator, n: int) -> Tensor:
    return torch.where(torch.rand(n, generator=gen) < 0.5, -1.0, 1.0).double()


def _radial(gen: torch.Generator, params: SpotlightParams, y: float, x: float) -> tuple:
    """A radial speed whose apparent azimuth ``x - R v_r / V`` lies in fold 0, +-1 or +-2."""
    fold = [0, 0, 1, -1, 2, -2][int(torch.randint(6, (1,), generator=gen))]
    period = params.geometry.unambiguous_azimuth * (1 + y / params.track.scene_range)
    apparent = (fold + float(_uniform(gen, 1, -FOLD_MARGIN, FOLD_MARGIN))) * period
    speed = (x - apparent) * params.track.platform_speed / (params.track.scene_range + y)
    return speed, fold


def _draw(gen: torch.Generator, params: SpotlightParams, radial: bool) -> Scene:
    """Kinds, positions, velocities and amplitudes of one scene (no separation check)."""
    kinds = [STILL] * int(torch.randint(6, 11, (1,), generator=gen))
    kinds += [ALONG] * int(torch.randint(1, 3, (1,), generator=gen)) + [RADIAL] * radial
    n = len(kinds)
    pos = torch.stack(
        [_uniform(gen, n, -RANGE_HALF, RANGE_HALF), _uniform(gen, n, -AZIMUTH_HALF, AZIMUTH_HALF)],
        -1,
    )
    vel = torch.zeros(n, 2, dtype=torch.float64)
    fold = torch.zeros(n, dtype=torch.long)
    kind = torch.tensor(kinds)
    along = kind == ALONG
    speed = _uniform(gen, int(along.sum()), 0.5, 13.0)
    vel[along, 1] = _sign(gen, int(along.sum())) * speed
    reach = (EDGE - speed * params.geometry.aperture_time).clamp(max=AZIMUTH_HALF)
    pos[along, 1] = (
        2 * torch.rand(int(along.sum()), generator=gen, dtype=torch.float64) - 1
    ) * reach
    if radial:
        vel[-1, 0], fold[-1] = _radial(gen, params, float(pos[-1, 0]), float(pos[-1, 1]))
    db = _uniform(gen, n, 0.0, 15.0)
    phase = _uniform(gen, n, 0.0, 2 * math.pi)
    amp = torch.polar(10 ** (db / 20), phase)
    centre = torch.zeros(1, 2, dtype=torch.float64)
    image = planar_image_positions(pos, params, centre, velocities=vel)[:, 0]
    return Scene(pos, vel, amp, kind, fold, image)


def _separated(scene: Scene, params: SpotlightParams) -> bool:
    """Every pair of targets ``MIN_SEPARATION`` apart in the image and in both looks of a
    two-look split (times ``+-T/4``), where movers have moved: a mover passing over another
    target within a resolution cell cannot be measured by any single-channel test."""
    period = torch.tensor(
        [params.geometry.unambiguous_range, params.geometry.unambiguous_azimuth],
        dtype=torch.float64,
    )
    for t in (-0.25, 0.0, 0.25):
        t = t * params.geometry.aperture_time
        shift = torch.stack(
            [
                -scene.fold.double() * params.geometry.blind_speed * t,
                look_displacement(scene.velocity[:, 1], t, params),
            ],
            -1,
        )
        at = scene.image + shift
        d = wrap(at[:, None] - at[None], period).norm(dim=-1)
        if bool((d + 1e9 * torch.eye(len(d))).min() < MIN_SEPARATION):
            return False
    return True


def random_scene(params: SpotlightParams, seed: int, index: int) -> Scene:
    """Scene ``index`` of ``seed``: a range mover when ``index`` is even."""
    gen = torch.Generator().manual_seed(image_seed(seed, index))
    while True:
        scene = _draw(gen, params, radial=index % 2 == 0)
        if _separated(scene, params):
            return scene


def random_scenes(
    params: SpotlightParams, seed: int, count: int, *, snr_db: float = 28.0, start: int = 0
) -> tuple[Tensor, list[Scene]]:
    """Noisy complex64 phase histories ``(count, M, K)`` of scenes ``start .. start + count``."""
    scenes = [random_scene(params, seed, i) for i in range(start, start + count)]
    g = simulate_phase_history(
        [s.position for s in scenes],
        params.geometry,
        velocities=[s.velocity for s in scenes],
        amplitudes=[s.amplitude for s in scenes],
    )
    std = image_noise_std(params.geometry, snr_db)
    noisy = [
        add_noise(g[i : i + 1], std=std, seed=image_seed(seed, i + start)) for i in range(count)
    ]
    return torch.cat(noisy).to(torch.complex64), scenes


@dataclass
class Tally:
    """A report scored against the truth of its scenes (the acceptance counts)."""

    along: int = 0  # along-track movers
    found: int = 0  # ... flagged mover
    accurate: int = 0  # ... with |v_est - v_true| <= max(3 %, 2 sigma)
    z: list = field(default_factory=list)  # (v_est - v_true) / sigma of each found mover
    false_movers: int = 0  # other detections (stationary, radial, ghosts) flagged mover
    folded: int = 0  # folded radial movers
    streaks: int = 0  # ... whose streak is detected
    radial_right: int = 0  # ... with exactly one detection there, flagged radial, right |fold|
    radial_elsewhere: int = 0  # radial flags on any other detection
    unfolded_flagged: int = 0  # unfolded radial movers flagged mover or radial
    misses: list = field(default_factory=list)  # descriptions of failures, for messages

    @property
    def rms_z(self) -> float:
        return math.sqrt(sum(z * z for z in self.z) / max(len(self.z), 1))


def _nearest(distance: Tensor, gate: float) -> dict[int, int]:
    """Truth index -> detection index, closest pairs first, one-to-one, within ``gate``."""
    pairs: dict[int, int] = {}
    if distance.shape[1] == 0:
        return pairs
    for j in distance.min(1).values.argsort().tolist():
        i = int(distance[j].argmin())
        if float(distance[j, i]) <= gate and i not in pairs.values():
            pairs[j] = i
    return pairs


def score(
    report, scenes: list[Scene], params: SpotlightParams, tally: Tally | None = None
) -> Tally:
    """Add the counts of ``report`` (a :class:`~torchsar.motion.MoverReport` of ``scenes``)."""
    tally = Tally() if tally is None else tally
    period = torch.tensor(
        [params.geometry.unambiguous_range, params.geometry.unambiguous_azimuth],
        dtype=torch.float64,
    )
    for b, scene in enumerate(scenes):
        n = int(report.valid[b].sum())
        offset = wrap(report.position[b, :n][None] - scene.image[:, None], period)  # (T, n, 2)
        pairs = _nearest(offset.norm(dim=-1), 2.5)
        mover, radial = report.mover[b, :n].cpu(), report.radial[b, :n].cpu()
        streak_hits = torch.zeros(n, dtype=torch.bool)
        for j, kind in enumerate(scene.kind.tolist()):
            i = pairs.get(j, -1)
            if kind == ALONG:
                _score_along(tally, report, b, i, float(scene.velocity[j, 1]))
            elif kind == RADIAL and int(scene.fold[j]) != 0:
                streak_hits |= _score_folded(
                    tally, report, b, offset[j], int(scene.fold[j]), params
                )
            elif kind == RADIAL:
                tally.unfolded_flagged += int(i >= 0 and bool(mover[i] | radial[i]))
        along = {pairs[j] for j, k in enumerate(scene.kind.tolist()) if k == ALONG and j in pairs}
        others = torch.ones(n, dtype=torch.bool)
        others[list(along)] = False
        tally.false_movers += int((mover & others).sum())
        tally.radial_elsewhere += int((radial & ~streak_hits).sum())
    return tally


def _score_along(tally: Tally, report, b: int, i: int, truth: float) -> None:
    tally.along += 1
    if i < 0 or not bool(report.mover[b, i]):
        tally.misses.append(f"scene {b}: along-track mover {truth:.2f} m/s not flagged")
        return
    tally.found += 1
    v, sigma = float(report.velocity[b, i]), float(report.sigma[b, i])
    tally.z.append((v - truth) / sigma)
    if abs(v - truth) <= max(0.03 * abs(truth), 2 * sigma):
        tally.accurate += 1
    else:
        tally.misses.append(f"scene {b}: {truth:.3f} m/s estimated {v:.3f} +- {sigma:.3f}")


def _score_folded(tally: Tally, report, b: int, offset: Tensor, fold: int, params) -> Tensor:
    """Detections on the streak of a folded radial mover (its column, +- its walk)."""
    tally.folded += 1
    half = abs(fold) * params.geometry.blind_speed * params.geometry.aperture_time / 2 + 2.0
    on = (offset[:, 1].abs() <= 2.0) & (offset[:, 0].abs() <= half)
    if not on.any():
        return on
    tally.streaks += 1
    flagged = report.radial[b, : len(on)].cpu() & on
    folds = report.fold[b, : len(on)].cpu()[flagged].abs().tolist()
    if int(on.sum()) == 1 and folds == [abs(fold)]:
        tally.radial_right += 1
    else:
        tally.misses.append(
            f"scene {b}: fold {fold} streak with {int(on.sum())} detections, radial folds {folds}"
        )
    return on
