"""Whole scenes in bounded memory: tiled execution of every detector and speckle filter.

A scene (tensor, numpy array, memmap or windowed reader, ``(H, W)`` intensity) is split
into tiles whose windows carry a halo derived from the operator's footprint; tiles are
read lazily, run in batches and their cores stitched, giving what the operator gives on
the whole image. :func:`run_scene` stitches per-pixel outputs, :func:`scene_objects` gives
one row per detected object with components merged across tile seams, and
:func:`region_scene` runs the region-growing CFAR, whose unbounded reach is settled by
enlarging and redoing tiles (:mod:`torchsar.tiling.region`).
"""

from torchsar.tiling.footprint import DETECTORS, Operator, operator
from torchsar.tiling.plan import Tile, plan_tiles
from torchsar.tiling.run import iter_tiles, run_scene
from torchsar.tiling.source import Scene, as_scene

__all__ = [
    "DETECTORS",
    "Operator",
    "Scene",
    "Tile",
    "as_scene",
    "iter_tiles",
    "operator",
    "plan_tiles",
    "run_scene",
]
