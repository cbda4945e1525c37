"""One ladder row per scene: what each test says about the mover and about everything else."""

from __future__ import annotations

import math

import torch
from torch import Tensor

from torchsar.motion import (
    MoverReport,
    SpotlightParams,
    doppler_fold,
    look_displacement,
    planar_image_positions,
    walk_rate,
)
from torchsar.motion import wrap as fold
from torchsar_eval.experiments.movers.scenes import MOVER

__all__ = ["TESTS", "scene_row"]

TESTS = {
    "look": "look",
    "focus": "focus",
    "subpatch": "subpatch",
    "combined": "mover",
    "radial": "radial",
}


def _flags(report: MoverReport) -> dict[str, Tensor]:
    """Per-test bool ``(B, N)`` decisions."""
    return {
        "look": report.look.mover,
        "focus": report.focus.mover,
        "subpatch": report.subpatch,
        "combined": report.mover,
        "radial": report.radial,
    }


def _match(
    report: MoverReport, b: int, pos: Tensor, vel: Tensor, params: SpotlightParams
) -> tuple[dict[int, int], set[int]]:
    """Target index of each layout point (3 m gate, wider for a fast mover) and the
    fragments of the mover (other peaks inside its smear)."""
    period = torch.tensor([params.geometry.unambiguous_range, params.geometry.unambiguous_azimuth])
    centre = torch.zeros(1, 2, dtype=torch.float64)
    pred = planar_image_positions(pos, params, centre, velocities=vel)[:, 0]
    ok = report.valid[b].cpu()
    d = fold(report.position[b][None] - pred[:, None], period.double())
    dist = torch.where(ok[None], d.norm(dim=-1), torch.inf)
    matched: dict[int, int] = {}
    for j in range(pos.shape[0]):
        gate = 3.0 + float(vel[j].norm()) * params.geometry.aperture_time
        if (
            dist.shape[1]
            and float(dist[j].min()) <= gate
            and int(dist[j].argmin()) not in matched.values()
        ):
            matched[j] = int(dist[j].argmin())
    fragments: set[int] = set()
    if pos.shape[0] > MOVER:
        walk = 3.0 + abs(float(vel[MOVER, 0])) * params.geometry.aperture_time
        smear = 3.0 + 2 * abs(float(vel[MOVER, 1])) * params.geometry.aperture_time
        near = (d[MOVER, :, 0].abs() <= walk) & (d[MOVER, :, 1].abs() <= smear) & ok
        fragments = {int(i) for i in near.nonzero().flatten()} - set(matched.values())
    return matched, fragments


def _mover_columns(report: MoverReport, b: int, i: int) -> dict:
    """Measured values of the mover's target ``i`` (NaN when not found)."""
    nan = float("nan")
    if i < 0:
        return {
            k: nan
            for k in (
                "look_shift_m",
                "look_range_shift_m",
                "look_velocity_mps",
                "focus_velocity_mps",
                "focus_gain_db",
                "velocity_mps",
                "velocity_sigma_mps",
                "mover_snr_db",
                "walk_mps",
                "fold",
                "radial_low_mps",
                "radial_high_mps",
            )
        }
    disp = report.look.displacement[b, i, -1]
    return {
        "look_shift_m": float(disp[1]),
        "look_range_shift_m": float(disp[0]),
        "look_velocity_mps": float(report.look.velocity[b, i]),
        "focus_velocity_mps": float(report.focus.velocity[b, i]),
        "focus_gain_db": 10 * math.log10(float(report.focus.gain[b, i])),
        "velocity_mps": float(report.velocity[b, i]),
        "velocity_sigma_mps": float(report.sigma[b, i]),
        "mover_snr_db": 10 * math.log10(float(report.focus.snr[b, i])),
        "walk_mps": float(report.look.walk[b, i]),
        "fold": int(report.fold[b, i]) if bool(report.radial[b, i]) else nan,
        "radial_low_mps": float(report.radial_speed[b, i, 0]),
        "radial_high_mps": float(report.radial_speed[b, i, 1]),
    }


def scene_row(
    report: MoverReport, b: int, pos: Tensor, vel: Tensor, params: SpotlightParams
) -> dict:
    """The ladder columns of scene ``b`` (``pos``/``vel`` ``(N, 2)``; no mover if N < 4)."""
    matched, fragments = _match(report, b, pos, vel, params)
    has_mover = pos.shape[0] > MOVER
    best = matched.get(MOVER, -1) if has_mover else -1
    still = {i for j, i in matched.items() if j != MOVER}
    targets = set(report.valid[b].nonzero().flatten().tolist())
    clutter = targets - still - fragments - {best}
    dt = float(report.plan.time[-1] - report.plan.time[0])
    v_a = float(vel[MOVER, 1]) if has_mover else 0.0
    k = int(doppler_fold(pos[MOVER], params, velocities=vel[MOVER])) if has_mover else 0
    row = {
        "theory_look_shift_m": look_displacement(v_a, dt, params),
        "theory_smear_m": 2 * abs(v_a) * params.geometry.aperture_time,
        "theory_fold": k,
        "theory_walk_mps": walk_rate(k, params),
        "mover_found": best >= 0,
        **_mover_columns(report, b, best),
        "stationary_found": len(still),
        "clutter_peaks": len(clutter),
        "fragments": len(fragments),
        "conflicts": int(report.conflict[b].sum()),
    }
    for name, flags in _flags(report).items():
        f = flags[b].cpu()
        row[f"{name}_detected"] = bool(best >= 0 and f[best])
        row[f"{name}_false_stationary"] = sum(bool(f[i]) for i in still)
        row[f"{name}_false_clutter"] = sum(bool(f[i]) for i in clutter)
    return row
