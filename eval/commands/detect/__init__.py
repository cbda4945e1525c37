"""``torchsar-eval detect``: run a detector over whole scenes, tile by tile, and write one
row per detected object.

Each scene file (GeoTIFF, BigTIFF, COG, Sentinel-1 GRD, SICD: whatever
:func:`torchsar.io.open_scene` reads) is read window by window and cut into tiles whose
objects are merged across seams (:mod:`torchsar.tiling`), so memory stays bounded
whatever the scene size. The run folder holds ``detections.csv`` (the columns of
:mod:`torchsar.tiling.table`), ``detections.geojson`` (points, when every scene maps to
lon/lat) and ``config.json`` (the options and each scene's manifest). Runs are atomic and
resumable like ``run``: finished tiles are saved in the staging folder and ``--resume``
continues a killed run (:mod:`torchsar_eval.commands.detect.tiles`).
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

from torchsar_eval.errors import EvalError

__all__ = ["add_parser", "run"]

SAMPLE_TYPES = ("amplitude", "intensity", "db", "complex")


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "detect",
        help="detect objects in whole scenes (tiled, bounded memory): detections.csv, "
        "detections.geojson",
        description="Run one detector over whole scene files tile by tile (objects merged "
        "across tile seams) and write detections.csv (xView3 columns), detections.geojson "
        "(when georeferenced) and config.json.",
    )
    p.add_argument(
        "--scene",
        metavar="FILE[,FILE...]",
        help="scene files (GeoTIFF, BigTIFF, COG, Sentinel-1 GRD, SICD; required); the scene "
        "id is each file's stem",
    )
    p.add_argument(
        "--detector",
        metavar="NAME",
        help="a window CFAR (ca, go, so, os, vi, ac, two_parameter, lognormal, weibull, "
        "gamma, k, g0) or region (required)",
    )
    p.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="detector option, e.g. guard=4 or pfa=1e-6 (repeatable)",
    )
    p.add_argument(
        "--tile",
        type=int,
        default=None,
        help="tile core side in pixels (default 1024; region 512); records and memory "
        "scale with it",
    )
    p.add_argument(
        "--sample-type",
        choices=SAMPLE_TYPES,
        default=None,
        help="what the samples are when the file does not say (Sentinel-1 GRD: amplitude, "
        "complex data: complex); windows are converted to intensity",
    )
    p.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    p.add_argument(
        "--engine",
        choices=["local", "ray"],
        default="local",
        help="local processes (ray is not supported by detect yet)",
    )
    p.add_argument("--device", default=None, help="where detectors run: cpu, cuda, cuda:N")
    p.add_argument(
        "--out", type=Path, default=None, help="output folder (default: results/detect-*)"
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the interrupted run in --out from its saved tiles (same scenes and options)",
    )
    p.add_argument(
        "--discard",
        action="store_true",
        help="delete the saved tiles an interrupted run of --out left, and start over",
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=run, claims_out=True)


def _check_args(args: argparse.Namespace) -> None:
    from torchsar_eval.options import at_least

    for flag, value in (("--scene", args.scene), ("--detector", args.detector)):
        if not value:
            raise EvalError(f"{flag} is required (see torchsar-eval detect --help)")
    if args.engine == "ray":
        raise EvalError(
            "--engine ray is not supported by detect yet: use --workers N (local processes)"
        )
    at_least(args.workers, "--workers", 1)
    at_least(args.tile, "--tile", 1)


def run(args: argparse.Namespace) -> int:
    """The ``detect`` sub-command: check everything, run the tiles, write the tables."""
    from torchsar_eval.output import check_out

    _check_args(args)
    check_out(args.out, overwrite=args.overwrite, resume=args.resume, discard=args.discard)

    from torchsar._checks import check_device
    from torchsar_eval.commands.detect import plan

    options = plan.parse_options(args.param)
    scenes = plan.open_scenes(args.scene, args.sample_type)
    check_device(args.device, "--device")
    for sc in scenes:
        tile, batch = plan.check_detector(args.detector, options, args.tile, sc)
    jobs = [
        plan.DetectJob(
            plan.Scene(sc.scene_id, sc.path, sc.shape, sc.sample_type, plan.grid(sc.shape, tile)),
            args.detector,
            options,
            tile,
            batch,
            args.device,
        )
        for sc in scenes
    ]
    fingerprint = _fingerprint(jobs)
    written = _execute(args, jobs, fingerprint)
    for line in written["lines"]:
        print(line)
    print(f"\nwrote {args.out}/: " + " ".join(written["files"]))
    return 0


def _fingerprint(jobs: list) -> dict:
    """What every saved tile depends on: a resumed run must match it."""
    import json

    from torchsar_eval.commands.detect.plan import scene_manifest

    j = jobs[0]
    return json.loads(
        json.dumps(
            {
                "command": "detect",
                "records": 1,
                "detector": j.detector,
                "options": j.options,
                "tile": list(j.tile),
                "connectivity": j.connectivity,
                "device": j.device,
                "scenes": [
                    {
                        "scene_id": x.scene.scene_id,
                        "sample_type": x.scene.sample_type,
                        "shape": list(x.scene.shape),
                    }
                    for x in jobs
                ],
                "manifests": {x.scene.scene_id: scene_manifest(Path(x.scene.path)) for x in jobs},
            },
            default=str,
        )
    )


def _prepared(job):
    """The job with AC-CFAR's scene clutter mean (one pass over the scene, in the driver)."""
    from dataclasses import replace

    from torchsar.tiling import operator
    from torchsar.tiling.run import prepare
    from torchsar_eval.commands.detect.tiles import scene_reader

    if job.detector != "ac":
        return job
    op = prepare(scene_reader(job), operator("ac", **job.options), tile=job.tile)
    return replace(job, clutter_mean=float(op.options["clutter_mean"]))


def _execute(args: argparse.Namespace, jobs: list, fingerprint: dict) -> dict:
    from tqdm.auto import tqdm

    from torchsar_eval.commands.detect import tiles
    from torchsar_eval.output import RESUMABLE, claim, result_dir
    from torchsar_eval.resume import check_resumable

    t0 = time.perf_counter()
    with (
        claim(
            args.out, overwrite=args.overwrite, resume=args.resume, discard=args.discard
        ) as target,
        result_dir(target, resume=args.resume, keep=True) as tmp,
    ):
        try:
            check_resumable(tmp / RESUMABLE, fingerprint)
            folders = [tmp / "tiles" / f"{k:03d}" for k in range(len(jobs))]
            for f in folders:
                f.mkdir(parents=True, exist_ok=True)
            todo = [tiles.pending(job, f) for job, f in zip(jobs, folders, strict=True)]
            total = sum(len(job.scene.tiles()) for job in jobs)
            reused = total - sum(map(len, todo))
            jobs = [_prepared(job) if t else job for job, t in zip(jobs, todo, strict=True)]
            tasks = [
                (job, chunk, f)
                for job, t, f in zip(jobs, todo, folders, strict=True)
                for chunk in tiles.chunks(t, job.batch)
            ]
            bar = tqdm(
                total=total, initial=reused, desc="detect", unit="tile", disable=args.no_progress
            )
            try:
                tiles.run_tasks(tasks, args.workers, bar)
            finally:
                bar.close()
            written = _write_outputs(tmp, jobs, folders)
        finally:
            tiles.close_readers()
        shutil.rmtree(tmp / "tiles")
        (tmp / RESUMABLE).unlink()
        _write_config(tmp, args, jobs, written, total, reused, time.perf_counter() - t0)
    written["files"].append("config.json")
    return written


def _write_outputs(tmp: Path, jobs: list, folders: list[Path]) -> dict:
    import pandas as pd

    from torchsar.io import open_scene
    from torchsar.tiling.table import detection_table, write_csv, write_geojson
    from torchsar_eval.commands.detect.tiles import scene_objects

    parts, lines, per_scene = [], [], []
    for job, folder in zip(jobs, folders, strict=True):
        sc = job.scene
        with open_scene(sc.path, sample_type=sc.sample_type) as reader:
            georef, spacing = reader.georef, reader.pixel_spacing
        table = detection_table(
            scene_objects(job, folder), sc.scene_id, georef=georef, pixel_spacing=spacing
        )
        parts.append(table)
        located = bool(table[["lon", "lat"]].notna().all().all()) and georef is not None
        per_scene.append(
            {
                "objects": len(table),
                "georeferenced": located,
                "pixel_spacing": None if spacing is None else list(spacing),
            }
        )
        lines.append(
            f"{sc.scene_id}: {len(table)} objects, {sc.grid[0] * sc.grid[1]} tiles "
            f"({sc.shape[0]}x{sc.shape[1]} px)"
        )
    table = pd.concat(parts, ignore_index=True)
    write_csv(table, tmp / "detections.csv")
    files = ["detections.csv"]
    if all(s["georeferenced"] for s in per_scene):
        write_geojson(table, tmp / "detections.geojson")
        files.append("detections.geojson")
        geojson = "written"
    else:
        names = [
            j.scene.scene_id for j, s in zip(jobs, per_scene, strict=True) if not s["georeferenced"]
        ]
        geojson = f"not written: no lon/lat for scene(s) {', '.join(names)}"
        lines.append(f"detections.geojson {geojson}")
    return {"files": files, "lines": lines, "scenes": per_scene, "geojson": geojson}


def _write_config(
    tmp: Path, args, jobs: list, written: dict, total: int, reused: int, wall: float
) -> None:
    from torchsar_eval.commands.detect.plan import min_size, scene_manifest
    from torchsar_eval.output import write_config

    j = jobs[0]
    scenes = [
        {
            "scene_id": x.scene.scene_id,
            "path": x.scene.path,
            "shape": list(x.scene.shape),
            "sample_type": x.scene.sample_type,
            "tiles": list(x.scene.grid),
            "clutter_mean": x.clutter_mean,
            "manifest": scene_manifest(Path(x.scene.path)),
            **s,
        }
        for x, s in zip(jobs, written["scenes"], strict=True)
    ]
    write_config(
        tmp,
        "detect",
        {
            "scenes": scenes,
            "detector": j.detector,
            "options": j.options,
            "tile": list(j.tile),
            "batch": j.batch,
            "connectivity": j.connectivity,
            "min_size": min_size(j.detector, j.options),
            "device": j.device,
            "workers": args.workers,
            "engine": args.engine,
            "point": "detect_scene_row/column: the peak pixel (highest statistic) of each object",
            "tiles_total": total,
            "tiles_reused": reused,
            "geojson": written["geojson"],
            "files": [*written["files"], "config.json"],
            "wall_s": round(wall, 3),
        },
    )
