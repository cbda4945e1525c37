"""Whole-scene entry points: per-pixel outputs (:func:`run_scene`) and the object table
(:func:`scene_objects`) of any detector, window CFAR or region CFAR, run tile by tile."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING

import numpy as np
import torch
from scipy import ndimage

from torchsar.errors import OptionError
from torchsar.region.params import resolve_params
from torchsar.tiling import region as _region
from torchsar.tiling import run as _run
from torchsar.tiling.footprint import operator
from torchsar.tiling.objects import SeamMerger
from torchsar.tiling.plan import Tile
from torchsar.tiling.source import Scene, as_scene, release

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["run_scene", "scene_objects"]

_REGION_ONLY = ("max_halo", "despeckle_reach", "preset")


def _tiles(
    sc: Scene,
    detector: str,
    tile: object,
    halo: object,
    batch: object,
    device: object,
    options: dict[str, object],
) -> Iterator[tuple[Tile, dict[str, np.ndarray]]]:
    if detector == "region":
        return _region.iter_region_tiles(
            sc,
            tile=_region.DEFAULT_TILE if tile is None else tile,
            halo=halo,
            batch=1 if batch is None else batch,
            device=device,
            **options,
        )  # type: ignore[arg-type]
    bad = sorted(set(options) & set(_REGION_ONLY))
    if bad:
        raise OptionError(f"{', '.join(bad)}: options of the region CFAR only, not of {detector}")
    return _run.iter_tiles(
        sc,
        detector,
        tile=_run.DEFAULT_TILE if tile is None else tile,
        halo=halo,
        batch=_run.DEFAULT_BATCH if batch is None else batch,
        device=device,
        **options,
    )  # type: ignore[arg-type]


def _min_size(detector: str, options: dict[str, object]) -> int:
    """The region CFAR's object-size rule (applied after merging across seams); 1 else."""
    if detector != "region":
        return 1
    opts = {k: v for k, v in options.items() if k not in _REGION_ONLY}
    return resolve_params(str(options.get("preset", "torchsar")), **opts).min_size  # type: ignore[arg-type]


def _out_arrays(
    names: tuple[str, ...],
    shape: tuple[int, int],
    dtype: np.dtype,
    out: Mapping[str, object] | None,
) -> dict[str, object]:
    arrays: dict[str, object] = {}
    for name in names:
        if out is not None and name in out:
            a = out[name]
            if tuple(getattr(a, "shape", ())) != shape:
                raise OptionError(
                    f"out[{name!r}] must have shape {shape}, got {getattr(a, 'shape', None)}"
                )
            arrays[name] = a
        else:
            arrays[name] = np.empty(shape, dtype=bool if name == "mask" else dtype)
    return arrays


def _outputs(detector: str) -> tuple[str, ...]:
    return ("mask", "statistic") if detector == "region" else operator(detector).outputs


def run_scene(
    scene: object,
    detector: str,
    *,
    tile: int | tuple[int, int] | None = None,
    halo: int | None = None,
    batch: int | None = None,
    device: str | torch.device | None = None,
    out: Mapping[str, object] | None = None,
    **options: object,
) -> dict[str, object]:
    """Run a detector or speckle filter over a whole scene in tiles; the stitched outputs
    equal the operator on the whole image.

    Window CFARs and the region CFAR give ``{"mask", "statistic"}``, speckle filters
    ``{"image"}``, each ``(H, W)``: new numpy arrays, or the caller's arrays passed in
    ``out`` by name (e.g. numpy memmaps: then no full-scene array is held in memory).

    Args:
        scene: 2-D intensity scene (tensor, numpy array, memmap or windowed reader; see
            :func:`~torchsar.tiling.as_scene`).
        detector: a window CFAR (``"ca"``, ``"os"``, ...), ``"region"`` or a speckle filter.
        tile: core side or ``(rows, cols)`` (default 1024).
        halo: pixels read around each core (default: the footprint reach; region: its first
            halo, see :mod:`torchsar.tiling.region`).
        batch: windows per call (default 4; region 1); results do not depend on it.
        device: where the operator runs (None: CPU).
        out: optional writable ``(H, W)`` arrays by output name.
        **options: the operator's options; region also ``preset``, ``max_halo`` and
            ``despeckle_reach``.

    Returns:
        The outputs by name.

    Memory: window operators about ``60-120 * batch * (tile + 2 halo)^2`` bytes
    (:mod:`torchsar.tiling.run`); region about
    ``150 * ((tile + 2 halo)^2 + (tile + 4 halo)^2)`` bytes per tile
    (:mod:`torchsar.tiling.region`); plus the outputs unless ``out`` holds them.

    Examples:
        >>> x = np.random.default_rng(0).exponential(size=(40, 50)).astype(np.float32)
        >>> x[20, 25] = 300.0
        >>> r = run_scene(x, "ca", tile=16, guard=1, train=2)
        >>> full = ts.cfar.ca(torch.from_numpy(x)[None, None], guard=1, train=2)
        >>> bool((r["mask"] == full.mask[0, 0].numpy()).all())
        True
    """
    sc = as_scene(scene)
    min_size = _min_size(detector, options)
    arrays = _out_arrays(_outputs(detector), sc.shape, sc.dtype, out)
    merger = SeamMerger(sc.shape) if min_size > 1 else None
    done: list[Tile] = []
    for t, res in _tiles(sc, detector, tile, halo, batch, device, dict(options)):
        res = _drop_inner_small(res, min_size)
        for name, v in res.items():
            arrays[name][t.core] = v  # type: ignore[index]
            release(arrays[name])  # a memmap's written pages leave the resident set
        if merger is not None:
            merger.add(t, res["mask"], res["statistic"])
            done.append(t)
    if merger is not None:
        _drop_small(arrays, merger, done, min_size)
    return arrays


def _drop_inner_small(res: dict[str, np.ndarray], min_size: int) -> dict[str, np.ndarray]:
    """The object-size rule on the objects that lie inside the core without touching its
    edge lines (they cannot merge with another tile's): dropped at once, so that the
    merger only keeps objects on seams and objects that stay (memory bounded by the tile
    perimeter and the detections, not by the clutter peaks of the whole scene)."""
    if min_size <= 1 or not res["mask"].any():
        return res
    mask = res["mask"]
    lab, n = ndimage.label(mask, structure=np.ones((3, 3), bool))
    small = np.bincount(lab.reshape(-1), minlength=n + 1) < min_size
    small[np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]])] = False
    small[0] = False
    drop = small[lab]
    if not drop.any():
        return res
    return {
        "mask": mask & ~drop,
        "statistic": np.where(drop, -np.inf, res["statistic"]).astype(res["statistic"].dtype),
    }


def _drop_small(arrays: dict, merger: SeamMerger, tiles: list[Tile], min_size: int) -> None:
    """The region CFAR's object-size rule on the stitched outputs: objects (8-connected,
    merged across seams) under ``min_size`` pixels lose their statistic (``-inf``)."""
    for t in tiles:
        mask = np.asarray(arrays["mask"][t.core])
        drop = merger.small(t, min_size)[merger.relabel(t, mask)]
        if drop.any():
            stat = np.array(arrays["statistic"][t.core])
            stat[drop] = -np.inf
            arrays["statistic"][t.core] = stat
            arrays["mask"][t.core] = mask & ~drop


def scene_objects(
    scene: object,
    detector: str,
    *,
    tile: int | tuple[int, int] | None = None,
    halo: int | None = None,
    batch: int | None = None,
    device: str | torch.device | None = None,
    connectivity: int = 2,
    **options: object,
) -> pd.DataFrame:
    """Run a detector over a scene tile by tile and return one row per detected object, in
    scene coordinates, with components merged across tile seams (no full-scene mask is
    ever allocated: per-tile aggregates and edge lines only).

    Objects are the ``connectivity``-connected components of the detector's mask (8 by
    default; the region CFAR's own object rule is 8-connected); the rows equal the
    components of the untiled mask. Columns: ``row``, ``col`` (centroid, float),
    ``peak_row``, ``peak_col`` (pixel of the highest statistic; ties: first in raster
    order), ``score`` (that statistic), ``area`` (pixels), ``row_min``, ``row_max``,
    ``col_min``, ``col_max`` (inclusive bounding box). Sorted by score (descending), then
    peak row and column. See :func:`run_scene` for the arguments.

    Raises:
        OptionError: a speckle filter (no mask), bad options; and the errors of
            :func:`run_scene`.

    Examples:
        >>> x = np.random.default_rng(0).exponential(size=(40, 50)).astype(np.float32)
        >>> x[15, 15] = x[16, 16] = 500.0  # touching diagonally across a tile corner
        >>> t = scene_objects(x, "ca", tile=16, guard=1, train=2, pfa=1e-6)
        >>> t[["area", "row_min", "row_max", "col_min", "col_max"]].values.tolist()
        [[2, 15, 16, 15, 16]]
    """
    sc = as_scene(scene)
    if "image" in _outputs(detector):
        raise OptionError(f"detector={detector!r} is a speckle filter: it has no objects")
    min_size = _min_size(detector, options)
    if min_size > 1 and connectivity != 2:
        raise OptionError(
            "connectivity must be 2 for the region CFAR with min_size > 1 (its object-size "
            "rule is on 8-connected objects)"
        )
    merger = SeamMerger(sc.shape, connectivity)
    for t, res in _tiles(sc, detector, tile, halo, batch, device, dict(options)):
        res = _drop_inner_small(res, min_size)
        merger.add(t, res["mask"], res["statistic"])
    table = merger.table()
    return table[table["area"] >= min_size].reset_index(drop=True)
