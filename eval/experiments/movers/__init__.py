"""``torchsar-eval movers``: moving targets found in clutter, a speed and SNR ladder.

Scenes: three stationary point targets and one mover (along-track or range, 0.39-15.6 m/s,
the seed paper's ladder; range movers from 2.34 m/s are Doppler-folded 1-5 times) in weak
distributed clutter (many random scatterers, clutter-to-noise
ratio ``--cnr-db``) and white noise (target peak SNR ``--snr-db``); along-track movers again
at every SNR of ``--snr-ladder``; control scenes without a mover. Each scene goes through
:func:`torchsar.motion.find_movers` (look test, focus test, subpatch test, combined
decision, radial flag with the fold). Writes ``movers.csv`` / ``movers.md`` (one row per
scene), ``sensitivity.csv``
(minimum detectable along-track speed per SNR), ``displacement.png`` and ``config.json``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING

from torchsar_eval.errors import EvalError

if TYPE_CHECKING:
    from torchsar_eval.experiments.movers.experiment import LadderConfig

__all__ = ["SPEEDS", "add_parser", "run"]

SPEEDS = (0.39, 0.78, 1.17, 1.56, 2.34, 3.12, 4.68, 6.24, 9.36, 12.48, 15.6)


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "movers",
        help="moving-target detection in clutter: look, focus and subpatch tests, speed ladder",
        description="Simulate point targets with one mover in clutter for a ladder of speeds "
        "and SNRs, run the look, focus and subpatch tests; write movers.csv, movers.md, "
        "sensitivity.csv, displacement.png, config.json.",
    )
    p.add_argument(
        "--out", type=Path, default=None, help="output folder (default results/movers-*)"
    )
    p.add_argument(
        "--size",
        type=int,
        default=1024,
        help="azimuth pixels (range pixels: a quarter; default 1024)",
    )
    p.add_argument(
        "--azimuth-resolution",
        type=float,
        default=0.3,
        help="sets the aperture: 0.3 m = 2.5 s, the seed's Table 1 (m)",
    )
    p.add_argument(
        "--speeds", default=",".join(map(str, SPEEDS)), help="comma-separated mover speeds in m/s"
    )
    p.add_argument("--directions", default="along-track,range", help="along-track, range or both")
    p.add_argument("--snr-db", type=float, default=30.0, help="image peak SNR of every target")
    p.add_argument(
        "--snr-ladder",
        default="15,20,25",
        help="further SNRs (dB) for along-track movers ('' for none)",
    )
    p.add_argument("--cnr-db", type=float, default=-5.0, help="clutter-to-noise ratio (dB)")
    p.add_argument("--clutter-points", type=int, default=400, help="scatterers per clutter field")
    p.add_argument("--clutter-fields", type=int, default=2, help="clutter realisations reused")
    p.add_argument("--controls", type=int, default=8, help="control scenes without a mover")
    p.add_argument("--looks", type=int, default=2, help="time sub-apertures (2-4)")
    p.add_argument("--overlap", type=float, default=0.0, help="overlap of the looks, [0, 1)")
    p.add_argument("--n-sigma", type=float, default=5.0, help="threshold of each test in sigmas")
    p.add_argument(
        "--max-fold",
        type=int,
        default=5,
        help="Doppler folds in the motion bank (5 covers 15.6 m/s radial)",
    )
    p.add_argument(
        "--no-subpatch",
        dest="subpatch",
        action="store_false",
        help="skip the subpatch test (it forms four more images per scene)",
    )
    p.add_argument("--batch-size", type=int, default=4, help="scenes imaged at once")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated scenes")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=run)


def floats(text: str, name: str, *, allow_empty: bool = False) -> tuple[float, ...]:
    """Comma-separated finite numbers; :class:`EvalError` naming ``name`` otherwise."""
    parts = [s.strip() for s in text.split(",") if s.strip()]
    try:
        values = tuple(float(s) for s in parts)
    except ValueError:
        raise EvalError(f"{name} must be comma-separated numbers, got {text!r}") from None
    if any(v != v or abs(v) == float("inf") for v in values) or (not values and not allow_empty):
        raise EvalError(f"{name} must be finite numbers, got {text!r}")
    return values


def config(args: argparse.Namespace) -> LadderConfig:
    """Validate the options (one-line errors) and freeze them."""
    from torchsar_eval.experiments.movers.experiment import LadderConfig

    speeds = floats(args.speeds, "--speeds")
    if min(speeds) <= 0:
        raise EvalError(f"--speeds must be > 0 m/s, got {args.speeds!r}")
    directions = tuple(d.strip() for d in args.directions.split(",") if d.strip())
    if not directions or any(d not in ("along-track", "range") for d in directions):
        raise EvalError(f"--directions must be along-track, range or both; got {args.directions!r}")
    checks = {
        "--size >= 128": args.size >= 128,
        "--batch-size >= 1": args.batch_size >= 1,
        "--clutter-points >= 0": args.clutter_points >= 0,
        "--clutter-fields >= 1": args.clutter_fields >= 1,
        "--controls >= 0": args.controls >= 0,
        "--looks in 2..4": 2 <= args.looks <= 4,
        "0 <= --overlap < 1": 0 <= args.overlap < 1,
        "--n-sigma > 0": args.n_sigma > 0,
        "--azimuth-resolution > 0": args.azimuth_resolution > 0,
        "0 <= --max-fold <= 8": 0 <= args.max_fold <= 8,
    }
    bad = [k for k, ok in checks.items() if not ok]
    if bad:
        raise EvalError(f"need {', '.join(bad)}")
    return LadderConfig(
        speeds=speeds,
        directions=directions,
        size=args.size,
        snr_db=args.snr_db,
        azimuth_resolution=args.azimuth_resolution,
        snr_ladder=floats(args.snr_ladder, "--snr-ladder", allow_empty=True),
        cnr_db=args.cnr_db,
        clutter_points=args.clutter_points,
        clutter_fields=args.clutter_fields,
        controls=args.controls,
        looks=args.looks,
        overlap=args.overlap,
        n_sigma=args.n_sigma,
        max_fold=args.max_fold,
        subpatch=args.subpatch,
        batch_size=args.batch_size,
        seed=args.seed,
        progress=not args.no_progress,
    )


def run(args: argparse.Namespace) -> int:
    import torch

    from torchsar_eval.experiments.movers.experiment import run_ladder
    from torchsar_eval.output import default_out

    cfg = config(args)
    out = args.out or default_out("movers")
    t0 = time.perf_counter()
    summary = run_ladder(cfg, out)
    print(summary)
    print(
        f"\nin {time.perf_counter() - t0:.1f} s ({torch.get_num_threads()} threads); wrote {out}/"
    )
    return 0
