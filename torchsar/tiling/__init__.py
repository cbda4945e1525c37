"""Whole scenes in bounded memory: tiled execution of every detector and speckle filter.

A scene (tensor, numpy array, memmap or windowed reader, ``(H, W)`` intensity) is split
into tiles whose windows carry a halo derived from the operator's footprint; tiles are
read lazily, run in batches and their cores stitched, giving what the operator gives on
the whole image. :func:`run_scene` stitches per-pixel outputs, :func:`scene_objects` gives
one row per detected object with components merged across tile seams, and
``detector="region"`` runs the region-growing CFAR, whose unbounded reach is settled by
enlarging and redoing tiles (:mod:`torchsar.tiling.region`).
"""

from torchsar.tiling.footprint import DETECTORS, Operator, operator
from torchsar.tiling.objects import COLUMNS, SeamMerger, components_table
from torchsar.tiling.plan import Tile, plan_tiles
from torchsar.tiling.region import UnsettledError, iter_region_tiles
from torchsar.tiling.run import iter_tiles
from torchsar.tiling.scene import run_scene, scene_objects
from torchsar.tiling.source import Scene, as_scene

__all__ = [
    "COLUMNS",
    "DETECTORS",
    "Operator",
    "Scene",
    "SeamMerger",
    "Tile",
    "UnsettledError",
    "as_scene",
    "components_table",
    "iter_region_tiles",
    "iter_tiles",
    "operator",
    "plan_tiles",
    "run_scene",
    "scene_objects",
]
