"""What a ``detect`` run is: its scenes (opened, identified, fingerprinted), the detector
and its options checked before any tile runs, and the tile grid of each scene."""

from __future__ import annotations

import ast
import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path

from torchsar_eval.errors import EvalError

__all__ = ["DetectJob", "Scene", "check_detector", "open_scenes", "parse_options", "scene_manifest"]

HEAD_BYTES = 1 << 20
"""Bytes of a scene file hashed into its manifest (the header and first tiles): with its
size and modification time, what tells a changed file on ``--resume`` without reading
every byte of a multi-GB scene."""

_REGION_ONLY = ("max_halo", "despeckle_reach", "preset")
_RUNNER = ("tile", "halo", "batch", "device", "only", "out", "valid", "clutter_mean")


@dataclass(frozen=True)
class Scene:
    """One scene of the run: ``scene_id`` (the file's stem), path, shape, what the
    samples are, and the tile grid ``(rows, cols)``."""

    scene_id: str
    path: str
    shape: tuple[int, int]
    sample_type: str
    grid: tuple[int, int] = (0, 0)

    def tiles(self) -> list[tuple[int, int]]:
        """Tile indices in raster order (the merge order)."""
        return [(i, j) for i in range(self.grid[0]) for j in range(self.grid[1])]


@dataclass(frozen=True)
class DetectJob:
    """What a worker needs to run tiles of one scene (picklable: paths and plain options).

    ``clutter_mean`` is AC-CFAR's scene-level statistic, computed once by the driver.
    """

    scene: Scene
    detector: str
    options: dict = field(default_factory=dict)
    tile: tuple[int, int] = (1024, 1024)
    batch: int = 4
    device: str | None = None
    clutter_mean: float | None = None
    connectivity: int = 2


def parse_options(items: list[str]) -> dict:
    """``["guard=3", "pfa=1e-6", "preset=paper"]`` -> ``{"guard": 3, "pfa": 1e-06, "preset":
    "paper"}`` (Python literals where they parse, else strings).

    Examples:
        >>> parse_options(["guard=3", "preset=paper"])
        {'guard': 3, 'preset': 'paper'}
    """
    out: dict = {}
    for item in items:
        key, eq, raw = item.partition("=")
        if not (eq and key.strip()) or len(item) > 1000:
            raise EvalError(f"--param must look like NAME=VALUE, got {item[:60]!r}")
        try:
            value = ast.literal_eval(raw)
        except (ValueError, SyntaxError, RecursionError, MemoryError):
            value = raw
        if key.strip() in _RUNNER:
            raise EvalError(
                f"--param {key.strip()}: set by detect itself (use --tile, "
                "--device); not a detector option"
            )
        out[key.strip()] = value
    return out


def scene_manifest(path: Path) -> dict:
    """The scene file's name, size and modification time (hashed as the dataset manifests
    are) and a sha256 of its first :data:`HEAD_BYTES` bytes."""
    from torchsar_eval.datasets.manifest import file_manifest

    out = file_manifest(path, [path])
    with open(path, "rb") as f:
        out["head_sha256"] = hashlib.sha256(f.read(HEAD_BYTES)).hexdigest()
    return out


def open_scenes(text: str, sample_type: str | None) -> list[Scene]:
    """The scenes of ``--scene FILE[,FILE...]``, each opened once to check it.

    Raises:
        EvalError: no scene, a missing file, two scenes with the same id, a scene whose
            sample type is unknown; FileFormatError (one line) for a file that is not a
            scene.
    """
    from torchsar.io import open_scene

    paths = [Path(p.strip()) for p in str(text).split(",") if p.strip()]
    if not paths:
        raise EvalError("--scene needs at least one scene file")
    scenes, seen = [], {}
    for p in paths:
        if not p.is_file():
            raise EvalError(f"--scene {p}: no such file")
        with open_scene(p, sample_type=sample_type) as reader:
            found = reader.sample_type
            shape = (int(reader.shape[0]), int(reader.shape[1]))
            if reader.raw_dtype.kind == "c":
                found = "complex"
        if found is None:
            raise EvalError(
                f"--scene {p} does not say what its samples are: pass "
                "--sample-type amplitude|intensity|db|complex"
            )
        sid = p.stem
        if sid in seen:
            raise EvalError(
                f"--scene {p} and {seen[sid]} have the same scene id {sid!r} "
                "(the file stem): rename one"
            )
        seen[sid] = p
        scenes.append(Scene(sid, str(p.resolve()), shape, found))
    return scenes


def min_size(detector: str, options: dict) -> int:
    """The region CFAR's object-size rule (on objects merged across seams); 1 else."""
    if detector != "region":
        return 1
    from torchsar.region.params import resolve_params

    opts = {k: v for k, v in options.items() if k not in _REGION_ONLY}
    return int(resolve_params(str(options.get("preset", "torchsar")), **opts).min_size)


def check_detector(detector: str, options: dict, tile: int | None, scene: Scene) -> tuple:
    """Check the detector, its options and the tile size on the scene before any tile
    runs (names, values on a small clutter image, tile against the footprint). Returns
    the tile ``(rows, cols)`` and batch.

    Raises:
        OptionError / EvalError: an unknown detector or option, a bad value, a tile
            smaller than the detector's footprint.
    """
    from torchsar.tiling import region as tregion
    from torchsar.tiling import run as trun
    from torchsar.tiling.footprint import DETECTORS, operator
    from torchsar_eval.options import dry_run

    tiny = _ShapeOnly(scene.shape)  # run with only=(): checks, no tile is read
    if detector == "region":
        size = tregion.DEFAULT_TILE if tile is None else tile
        for _ in tregion.iter_region_tiles(tiny, tile=size, only=(), **options):
            pass
        return _pair(size), 1
    if detector not in DETECTORS:
        names = ", ".join(sorted([*DETECTORS, "region"]))
        raise EvalError(f"--detector must be one of {names}; got {detector!r}")
    bad = sorted(set(options) & set(_REGION_ONLY))
    if bad:
        raise EvalError(f"--param {', '.join(bad)}: options of the region CFAR only")
    op = operator(detector, **options)
    dry_run(DETECTORS[detector], options, f"detector {detector}")
    size = trun.DEFAULT_TILE if tile is None else tile
    if op.name == "ac":
        op = op.with_options(clutter_mean=1.0)  # checks only: the scene's is computed later
    for _ in trun.iter_tiles(tiny, op, tile=size, only=()):
        pass
    return _pair(size), trun.DEFAULT_BATCH


class _ShapeOnly:
    """A scene of the right shape that is never read (the tile checks need the shape)."""

    def __init__(self, shape: tuple[int, int]) -> None:
        import numpy as np

        self.shape, self.dtype = shape, np.dtype(np.float32)

    def __getitem__(self, window: object) -> object:
        raise AssertionError("the checks read no pixel")


def _pair(size: int) -> tuple[int, int]:
    return (int(size), int(size))


def grid(shape: tuple[int, int], tile: tuple[int, int]) -> tuple[int, int]:
    """Tile rows and columns of a scene (cores of ``tile``, the last ones the remainder)."""
    return (math.ceil(shape[0] / tile[0]), math.ceil(shape[1] / tile[1]))
