"""The ladder run: scenes in batches through ``find_movers``, tables, figure, summary."""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass
from pathlib import Path

import pandas as pd
import torch
from tqdm import tqdm

from torchsar.motion import SpotlightParams, find_movers
from torchsar_eval.experiments.movers.ladder import scene_row
from torchsar_eval.experiments.movers.scenes import LAYOUT, MOVER, make_clutter, simulate_scenes
from torchsar_eval.output import result_dir, write_config
from torchsar_eval.tables import markdown

__all__ = ["SHOWN", "LadderConfig", "run_ladder", "sensitivity"]

SHOWN = [
    "kind",
    "direction",
    "speed_mps",
    "snr_db",
    "theory_look_shift_m",
    "look_shift_m",
    "theory_smear_m",
    "focus_gain_db",
    "velocity_mps",
    "look_detected",
    "focus_detected",
    "subpatch_detected",
    "combined_detected",
    "combined_false_stationary",
    "combined_false_clutter",
    "theory_fold",
    "fold",
    "radial_detected",
    "radial_false_stationary",
    "radial_false_clutter",
]
AXIS = {"along-track": 1, "range": 0}

SCOPE = """\
Scope (single-channel SAR): along-track motion changes the azimuth FM rate, so a mover is
displaced between time sub-aperture looks by (2 v_a - v_a^2/V) dt and focuses best at v_a:
both tests measure it and must agree ('combined'). Radial (range) motion is, to first order,
a stationary target displaced in azimuth by R v_r / V. When that leaves the sampled azimuth
extent (|x - R v_r / V| > lambda PRF R / 4V) the Doppler folds (fold k), and the image keeps
a residual range walk of k lambda PRF / 2 per second: the looks see it, the motion bank
compacts it, and the 'radial' flag reports k (not v_r: the true azimuth is unknown). An
unfolded radial mover shows nothing. The subpatch test responds to azimuth ambiguity, not
to motion."""


@dataclass(frozen=True)
class LadderConfig:
    """Resolved options of ``torchsar-eval movers``."""

    speeds: tuple[float, ...]
    directions: tuple[str, ...]
    size: int
    snr_db: float
    azimuth_resolution: float
    snr_ladder: tuple[float, ...]
    cnr_db: float
    clutter_points: int
    clutter_fields: int
    controls: int
    looks: int
    overlap: float
    n_sigma: float
    max_fold: int
    subpatch: bool
    batch_size: int
    seed: int
    progress: bool


def _params(cfg: LadderConfig) -> SpotlightParams:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return SpotlightParams.from_system(
            image_size=(cfg.size // 4, cfg.size), azimuth_resolution=cfg.azimuth_resolution
        )


def _scenes(cfg: LadderConfig) -> list[dict]:
    """One dict per scene: kind, direction, speed, snr."""
    rows = [
        {"kind": "ladder", "direction": d, "speed_mps": s, "snr_db": cfg.snr_db}
        for d in cfg.directions
        for s in cfg.speeds
    ]
    if "along-track" in cfg.directions:
        rows += [
            {"kind": "snr", "direction": "along-track", "speed_mps": s, "snr_db": snr}
            for snr in cfg.snr_ladder
            for s in cfg.speeds
        ]
    rows += [
        {"kind": "control", "direction": "none", "speed_mps": 0.0, "snr_db": cfg.snr_db}
        for _ in range(cfg.controls)
    ]
    return [{**r, "seed": cfg.seed + 1 + i} for i, r in enumerate(rows)]


def _batch(cfg, params, clutter, scenes: list[dict]) -> list[dict]:
    """Simulate, decide and tabulate scenes of one kind."""
    vel = torch.zeros(len(scenes), 2, dtype=torch.float64)
    for i, s in enumerate(scenes):
        if s["direction"] in AXIS:
            vel[i, AXIS[s["direction"]]] = s["speed_mps"]
    control = scenes[0]["kind"] == "control"
    g, pos = simulate_scenes(
        params,
        vel,
        snr_db=torch.tensor([s["snr_db"] for s in scenes]),
        cnr_db=cfg.cnr_db,
        clutter=clutter,
        seeds=torch.tensor([s["seed"] for s in scenes]),
        mover=not control,
    )
    report = find_movers(
        g,
        params,
        looks=cfg.looks,
        overlap=cfg.overlap,
        n_sigma=cfg.n_sigma,
        max_fold=cfg.max_fold,
        subpatch=cfg.subpatch and scenes[0]["kind"] == "ladder",
        max_targets=128,
    )
    full_vel = torch.zeros(len(scenes), len(LAYOUT), 2, dtype=torch.float64)
    full_vel[:, MOVER] = vel
    return [
        {**s, **scene_row(report, b, pos[b], full_vel[b, : pos.shape[1]], params)}
        for b, s in enumerate(scenes)
    ]


def sensitivity(table: pd.DataFrame) -> pd.DataFrame:
    """Smallest along-track speed from which every faster one is detected, per SNR and test."""
    out = []
    along = table[table.direction == "along-track"]
    for snr, part in along.groupby("snr_db"):
        part = part.sort_values("speed_mps")
        row = {"snr_db": snr}
        for test in ("look", "focus", "combined"):
            ok = part[f"{test}_detected"].to_numpy()
            missed = [i for i, v in enumerate(ok) if not v]
            last = missed[-1] + 1 if missed else 0
            speeds = part.speed_mps.tolist()
            row[f"{test}_min_speed_mps"] = speeds[last] if last < len(speeds) else float("nan")
        out.append(row)
    return pd.DataFrame(out)


def run_ladder(cfg: LadderConfig, out: Path) -> str:
    """Run every scene, write the run folder, return the printed summary."""
    params = _params(cfg)
    clutter = make_clutter(
        params,
        points=cfg.clutter_points,
        realisations=cfg.clutter_fields,
        seed=cfg.seed,
        size=params.image_size,
    )
    scenes = _scenes(cfg)
    rows: list[dict] = []
    bar = tqdm(total=len(scenes), disable=not cfg.progress, desc="movers")
    kinds = [[s for s in scenes if s["kind"] == k] for k in ("ladder", "snr", "control")]
    for group in kinds:
        for i in range(0, len(group), cfg.batch_size):
            rows += _batch(cfg, params, clutter, group[i : i + cfg.batch_size])
            bar.update(len(group[i : i + cfg.batch_size]))
    bar.close()
    table = pd.DataFrame(rows)
    sens = sensitivity(table)
    _write(out, table, sens, params, cfg)
    return _summary(table, sens)


def _summary(table: pd.DataFrame, sens: pd.DataFrame) -> str:
    shown = table[[c for c in SHOWN if c in table]]
    false = {
        t: int(table[f"{t}_false_stationary"].sum() + table[f"{t}_false_clutter"].sum())
        for t in ("look", "focus", "subpatch", "combined", "radial")
    }
    controls = table[table.kind == "control"]
    ranged = table[table.direction == "range"]
    flagged = ", ".join(
        f"{r.speed_mps:g} m/s: fold {r.theory_fold:d} "
        + (f"found {r.fold:.0f}" if r.radial_detected else "not flagged")
        for r in ranged[ranged.theory_fold != 0].itertuples()
    )
    along = ranged[ranged.combined_detected]
    misread = ", ".join(f"{r.speed_mps:g} m/s" for r in along.itertuples())
    lines = [
        shown.to_string(index=False, float_format=lambda v: f"{v:.3g}"),
        "",
        "minimum detectable along-track speed (m/s) per SNR:",
        sens.to_string(index=False, float_format=lambda v: f"{v:.3g}"),
        "",
        "false movers over all scenes: " + ", ".join(f"{k} {v}" for k, v in false.items()),
        f"control scenes: {len(controls)}, clutter peaks tested {int(table.clutter_peaks.sum())}",
        f"folded range movers (fold from the range walk): {flagged or 'none'}",
        f"range movers read as along-track movers: {misread or 'none'}",
        "",
        SCOPE,
    ]
    return "\n".join(lines)


def _write(out: Path, table, sens, params: SpotlightParams, cfg: LadderConfig) -> None:
    from torchsar_eval.experiments.movers.plots import plot_displacement

    with result_dir(out) as tmp:
        table.to_csv(tmp / "movers.csv", index=False)
        sens.to_csv(tmp / "sensitivity.csv", index=False)
        (tmp / "movers.md").write_text(markdown(table[[c for c in SHOWN if c in table]]))
        plot_displacement(table, tmp / "displacement.png")
        write_config(
            tmp,
            "movers",
            {
                **asdict(cfg),
                "params": asdict(params),
                "derived": {
                    "n_pulses": params.geometry.pulses,
                    "aperture_time_s": params.geometry.aperture_time,
                    "range_resolution_m": params.geometry.range_resolution,
                    "pixel_spacing_m": params.pixel_spacing,
                    "blind_speed_mps": params.geometry.blind_speed,
                },
                "consistency_notes": params.consistency_report(),
                "layout": LAYOUT,
                "mover_index": MOVER,
                "out": str(out),
            },
        )
