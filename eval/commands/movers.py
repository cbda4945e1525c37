"""``torchsar-eval movers``: the subpatch moving-target velocity ladder (seed Yusufoglu & Kartal).

The paper's scene: four point targets, three stationary and the right-most one moving, in
range only or in azimuth only, at speeds from 0.39 to 15.6 m/s, Table 1 system. For every
speed and direction the deramped data are simulated, four subpatch images formed, targets
detected (CA-CFAR) and associated, their displacements measured by sub-pixel
cross-correlation and the mover decision taken (:func:`torchsar.motion.find_movers`).

Two decisions per scene: the seed's (raw displacements against the median pattern of the
targets, tolerance from the pooled robust spread) and the distortion-corrected one (planar
distortion removed, noise-derived CRLB tolerance; columns ``*_corrected``). The theory
columns apply the same estimator to the planar-model predicted image positions
(:mod:`torchsar.motion.theory`). For range motion a control scene replaces the mover by a
stationary target at its apparent position ``(y + v x / V, x - v R / V)``
(``lookalike_flagged*``): when that look-alike is flagged as well, the detection is azimuth
ambiguity, not motion.

Writes ``movers.csv`` / ``movers.md`` (one row per direction and speed), ``config.json``, and
figures: ``pairs_range.png`` / ``pairs_azimuth.png`` (displacement of each target pair per
subpatch, the paper's Figures 5-8) and ``ladder.png`` (measured vs theoretical displacement).
"""

from __future__ import annotations

import argparse
import math
import time
import warnings
from pathlib import Path

import pandas as pd
import torch
from tqdm import tqdm

from eval.output import default_out, result_dir, write_config
from eval.tables import markdown
from torchsar.motion import (
    SpotlightParams,
    detect_movers,
    find_movers,
    folded_speed,
    planar_image_positions,
    scene_positions,
    simulate_phase_history,
)
from torchsar.motion.pipeline import MoverResult
from torchsar.motion.theory import _wrap

__all__ = ["LAYOUT", "add_parser", "run"]

# (range, azimuth) m: three stationary targets and the right-most (largest azimuth) mover.
# Azimuth within +-25 m and range within +-40 m keep every target inside all four subpatch
# images (sampled extents 180 m x 150 m around centres at +-50 m).
LAYOUT = ((-25.0, -20.0), (20.0, -8.0), (-5.0, 6.0), (10.0, 20.0))
MOVER = 3
SPEEDS = (0.39, 0.78, 1.17, 1.56, 2.34, 3.12, 4.68, 6.24, 9.36, 12.48, 15.6)
DIRECTIONS = {"range": 0, "azimuth": 1}
PAPER = {0.39: 0.78, 15.6: 10.1}  # reported mover-stationary displacement, range motion
SHOWN = [
    "direction",
    "speed_mps",
    "measured_shift_m",
    "theory_shift_m",
    "unaliased_theory_m",
    "detected",
    "false_movers",
    "measured_shift_corrected_m",
    "theory_shift_corrected_m",
    "detected_corrected",
    "false_movers_corrected",
    "lookalike_flagged_corrected",
]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "movers",
        help="subpatch moving-target detection: the velocity ladder (range and azimuth motion)",
        description="Simulate the seed paper's four-target scene for a ladder of speeds, detect "
        "the mover from subpatch displacements; write movers.csv, movers.md, figures, "
        "config.json.",
    )
    p.add_argument(
        "--out", type=Path, default=None, help="output folder (default results/movers-*)"
    )
    p.add_argument("--size", type=int, default=1024, help="image side in pixels (default 1024)")
    p.add_argument(
        "--speeds",
        default=",".join(map(str, SPEEDS)),
        help="comma-separated mover speeds in m/s (default: the paper's 0.39..15.6 ladder)",
    )
    p.add_argument("--directions", default="range,azimuth", help="range, azimuth or both")
    p.add_argument("--snr-db", type=float, default=30.0, help="image peak SNR of a point target")
    p.add_argument("--n-sigma", type=float, default=5.0, help="mover threshold in sigmas")
    p.add_argument("--azimuth-resolution", type=float, default=0.3, help="sets the aperture (m)")
    p.add_argument("--figure-speed", type=float, default=2.34, help="speed of the pair figures")
    p.add_argument("--batch-size", type=int, default=2, help="scenes imaged at once")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--no-control",
        dest="control",
        action="store_false",
        help="skip the control scenes (each mover replaced by a stationary target at its "
        "apparent position; doubles the run time)",
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=run)


def _params(args: argparse.Namespace) -> tuple[SpotlightParams, list[str]]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        params = SpotlightParams(
            image_size=(args.size, args.size), azimuth_resolution=args.azimuth_resolution
        )
    return params, params.consistency_report()


def _noise_std(params: SpotlightParams, snr_db: float) -> float:
    """Per-sample noise giving image peak SNR ``snr_db`` for a unit point (Hann in 2-D)."""
    m, k = params.n_pulses, params.n_samples
    gain = (0.5 * m * 0.5 * k) / math.sqrt(0.375 * m * 0.375 * k)  # sum w / sqrt(sum w^2)
    return gain * 10 ** (-snr_db / 20)


def _scenes(speeds: list[float], axis: int) -> tuple[torch.Tensor, torch.Tensor]:
    pos = torch.tensor(LAYOUT, dtype=torch.float64).expand(len(speeds), -1, -1).clone()
    vel = torch.zeros_like(pos)
    vel[:, MOVER, axis] = torch.tensor(speeds, dtype=torch.float64)
    return pos, vel


def run(args: argparse.Namespace) -> int:
    speeds = [float(s) for s in args.speeds.split(",") if s.strip()]
    directions = [d.strip() for d in args.directions.split(",") if d.strip()]
    bad = [d for d in directions if d not in DIRECTIONS]
    if bad or not speeds or args.size < 64 or args.batch_size < 1:
        raise SystemExit(
            f"torchsar-eval: error: need speeds, --size >= 64, --batch-size >= 1 and directions "
            f"in {list(DIRECTIONS)}; got directions {directions}, size {args.size}"
        )
    params, notes = _params(args)
    torch.manual_seed(args.seed)
    out = args.out or default_out("movers")
    t0 = time.perf_counter()
    rows, pair_data = [], {}
    bar = tqdm(total=len(speeds) * len(directions), disable=args.no_progress, desc="movers")
    for direction in directions:
        for start in range(0, len(speeds), args.batch_size):
            chunk = speeds[start : start + args.batch_size]
            axis = DIRECTIONS[direction]
            result, pos, vel = _analyse(params, chunk, axis, args)
            control = _control_columns(params, chunk, axis, args) if args.control else None
            for b, speed in enumerate(chunk):
                row = _row(direction, speed, b, result, pos[b], vel[b], params, args)
                rows.append({**row, **(control[b] if control else {})})
                if math.isclose(speed, args.figure_speed):
                    pair_data[direction] = _pair_positions(result, b, pos[b], vel[b], params)
            bar.update(len(chunk))
    bar.close()
    seconds = time.perf_counter() - t0
    table = pd.DataFrame(rows)
    _write(out, table, pair_data, params, notes, args, seconds)
    print("\n".join(f"note: {n}" for n in notes))
    print(
        table[[c for c in SHOWN if c in table]].to_string(
            index=False, float_format=lambda v: f"{v:.3g}"
        )
    )
    print(
        f"\n{len(rows)} scenes in {seconds:.1f} s ({torch.get_num_threads()} threads); wrote {out}/"
    )
    return 0


def _apparent(pos: torch.Tensor, vel: torch.Tensor, params: SpotlightParams) -> torch.Tensor:
    """Stationary look-alike of each mover: ``(y + v_r x / V, x - v_r (R0 + y) / V)``."""
    y, x, v = pos[..., 0], pos[..., 1], vel[..., 0]
    speed = params.platform_speed
    return torch.stack([y + v * x / speed, x - v * (params.scene_range + y) / speed], dim=-1)


def _analyse(
    params: SpotlightParams,
    speeds: list[float],
    axis: int,
    args: argparse.Namespace,
    control: bool = False,
) -> tuple[MoverResult, torch.Tensor, torch.Tensor]:
    """Image and decide a batch of scenes; ``control`` replaces the mover by its look-alike."""
    pos, vel = _scenes(speeds, axis)
    if control:
        pos[:, MOVER] = _apparent(pos[:, MOVER], vel[:, MOVER], params)
        vel = torch.zeros_like(vel)
    gen = torch.Generator().manual_seed(args.seed + 1000 * axis + int(100 * speeds[0]))
    g = simulate_phase_history(
        pos, params, velocities=vel, noise_std=_noise_std(params, args.snr_db), generator=gen
    ).to(torch.complex64)
    return find_movers(g, params, n_sigma=args.n_sigma), pos, vel


def _control_columns(params, speeds, axis, args) -> list[dict]:
    """Is the mover's stationary look-alike flagged too? (one dict per speed)."""
    result, pos, vel = _analyse(params, speeds, axis, args, control=True)
    raw = detect_movers(result.tracks.excess, n_sigma=args.n_sigma, min_sigma=0.01)
    out = []
    for b in range(len(speeds)):
        matched, near = _match(result, b, pos[b], vel[b], params)
        best = matched.get(MOVER, -1)
        out.append(
            {
                "lookalike_flagged": _flags(raw.mover[b], best, near)[0],
                "lookalike_flagged_corrected": _flags(result.decision.mover[b], best, near)[0],
            }
        )
    return out


def _period(params: SpotlightParams) -> torch.Tensor:
    return torch.tensor([params.unambiguous_range, params.unambiguous_azimuth], dtype=torch.float64)


def _match(
    result: MoverResult, b: int, pos: torch.Tensor, vel: torch.Tensor, params: SpotlightParams
) -> tuple[dict[int, int], list[int]]:
    """Track of each stationary target (3 m gate) and the tracks within the mover's gate."""
    tp = result.tracks.position[b, :, 0]
    ok = result.tracks.valid[b, :, 0]
    pred = planar_image_positions(pos, params, result.centers, velocities=vel)[:, 0]
    dist = _wrap(tp[None] - pred[:, None], _period(params)).norm(dim=-1)
    dist = torch.cat(
        [
            torch.where(ok[None], dist, torch.inf),
            torch.full((len(LAYOUT), 1), torch.inf, dtype=dist.dtype),
        ],
        1,
    )
    matched: dict[int, int] = {}
    for j in range(len(LAYOUT)):
        if j != MOVER and float(dist[j].min()) <= 3.0:
            matched[j] = int(dist[j].argmin())
    gate = 3.0 + float(vel[MOVER].norm()) * params.aperture_time
    order = dist[MOVER].argsort().tolist()
    near = [i for i in order if float(dist[MOVER, i]) <= gate and i not in matched.values()]
    if near:
        matched[MOVER] = near[0]
    return matched, near


def _theory(pos, vel, params: SpotlightParams, centers) -> tuple[float, float]:
    """Planar-model mover residual (max over subpatches, m): (raw, distortion-corrected).

    The same estimator as the measurement (median pattern over the four targets) applied to
    the predicted image positions (:func:`torchsar.motion.planar_image_positions`).
    """
    pred = planar_image_positions(pos, params, centers, velocities=vel)
    raw = _wrap(pred - pred[:, :1] - (centers[0] - centers), _period(params))
    s = scene_positions(pred, params, centers)
    corr = _wrap(s - s[:, :1], _period(params))
    return tuple(
        float(detect_movers(d[None], sigma=1.0).residual[0, MOVER].norm(dim=-1).max())
        for d in (raw, corr)
    )


def _flags(mover: torch.Tensor, best: int, near: list[int]) -> tuple[bool, int, int]:
    """(mover's track flagged, flagged tracks outside the mover's gate, flagged fragments).

    Fragments: other tracks inside the mover's gate (pieces of a smeared mover), counted
    neither as detection nor as false movers.
    """
    flagged = mover.nonzero().flatten().tolist()
    detected = best >= 0 and best in flagged
    return (
        detected,
        sum(i not in near for i in flagged),
        sum(i in near and i != best for i in flagged),
    )


def _nanmax(x: torch.Tensor) -> float:
    x = x[~torch.isnan(x)]
    return float(x.max()) if x.numel() else float("nan")


def _decision_columns(dec, b: int, best: int, near: list[int], n_sigma: float, tag: str) -> dict:
    detected, false, fragments = _flags(dec.mover[b], best, near)
    nan = float("nan")
    ok = best >= 0
    return {
        f"measured_shift{tag}_m": _nanmax(dec.residual[b, best].norm(dim=-1)) if ok else nan,
        f"detected{tag}": detected,
        f"false_movers{tag}": false,
        f"fragments_flagged{tag}": fragments,
        f"score{tag}": float(dec.score[b, best]) if ok else nan,
        f"tolerance{tag}_m": n_sigma * float(dec.sigma[b, best].max()) if ok else nan,
    }


def _still_score(dec, b: int, matched: dict[int, int]) -> float:
    """Largest decision score among the tracks of the stationary targets."""
    idx = [i for j, i in matched.items() if j != MOVER]
    return _nanmax(dec.score[b, idx]) if idx else float("nan")


def _row(direction, speed, b, result, pos, vel, params, args) -> dict:
    matched, near = _match(result, b, pos, vel, params)
    best = matched.get(MOVER, -1)
    raw = detect_movers(result.tracks.excess, n_sigma=args.n_sigma, min_sigma=0.01)
    v_r = speed if direction == "range" else 0.0
    v_a = speed if direction == "azimuth" else 0.0
    spread = float((result.centers - result.centers[0]).norm(dim=-1).max())
    theory_raw, theory_corr = _theory(pos, vel, params, result.centers)
    snr = float(result.tracks.snr[b, best]) if best >= 0 else float("nan")
    return {
        "direction": direction,
        "speed_mps": speed,
        **_decision_columns(raw, b, best, near, args.n_sigma, ""),
        "theory_shift_m": theory_raw,
        "unaliased_theory_m": abs(v_r) * spread / params.platform_speed,
        **_decision_columns(result.decision, b, best, near, args.n_sigma, "_corrected"),
        "theory_shift_corrected_m": theory_corr,
        "stationary_found": sum(j in matched for j in range(len(LAYOUT)) if j != MOVER),
        "stationary_max_score_corrected": _still_score(result.decision, b, matched),
        "stationary_max_score": _still_score(raw, b, matched),
        "tracks": int(result.tracks.valid[b, :, 0].sum()),
        "mover_snr_db": 10 * math.log10(snr) if snr == snr else snr,
        "doppler_hz": 2 * v_r / params.wavelength,
        "folded_speed_mps": folded_speed(v_r, params),
        "azimuth_offset_m": params.scene_range * v_r / params.platform_speed,
        "range_walk_m": abs(v_r) * params.aperture_time,
        "azimuth_smear_m": 2 * abs(v_a) * params.aperture_time,
    }


def _pair_positions(result, b, pos, vel, params) -> dict[str, torch.Tensor]:
    """Raw and distortion-corrected image positions ``(P, 2)`` of each matched target."""
    matched, _ = _match(result, b, pos, vel, params)
    out = {}
    for j, i in sorted(matched.items()):
        label = "M" if j == MOVER else str(j + 1)
        raw = result.tracks.position[b, i]
        out[label] = (raw, scene_positions(raw, params, result.centers) - result.centers)
    return out


def _write(out, table, pair_data, params, notes, args, seconds) -> None:
    from eval.motion_plots import plot_ladder, plot_pairs

    with result_dir(out) as tmp:
        table.to_csv(tmp / "movers.csv", index=False)
        (tmp / "movers.md").write_text(markdown(table[[c for c in SHOWN if c in table]]))
        for direction, data in pair_data.items():
            plot_pairs(
                data,
                tmp / f"pairs_{direction}.png",
                f"{direction} motion, {args.figure_speed:g} m/s",
                _period(params),
            )
        plot_ladder(table, PAPER, tmp / "ladder.png")
        write_config(
            tmp,
            "movers",
            {
                "params": {k: getattr(params, k) for k in params.__dataclass_fields__},
                "derived": {
                    "bandwidth_hz": params.bandwidth,
                    "range_resolution_m": params.range_resolution,
                    "n_pulses": params.n_pulses,
                    "aperture_time_s": params.aperture_time,
                    "unambiguous_range_m": params.unambiguous_range,
                    "unambiguous_azimuth_m": params.unambiguous_azimuth,
                    "blind_speed_mps": params.blind_speed,
                    "pixel_spacing_m": params.pixel_spacing,
                },
                "consistency_notes": notes,
                "layout": LAYOUT,
                "mover_index": MOVER,
                "speeds": table.speed_mps.unique().tolist(),
                "snr_db": args.snr_db,
                "n_sigma": args.n_sigma,
                "seed": args.seed,
                "batch_size": args.batch_size,
                "threads": torch.get_num_threads(),
                "seconds": seconds,
                "out": str(out),
            },
        )
