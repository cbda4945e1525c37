"""Run a window operator over a scene tile by tile, batched, and stitch the cores.

Memory rule (window CFARs and speckle filters): a batch holds ``batch`` windows of
``(tile + 2 halo)^2`` pixels; the operator's own work per window is strip-bounded, so the
peak is about ``c * batch * (tile + 2 * halo)^2`` bytes over the interpreter and torch
(about 0.3 GB), with ``c`` around 60 for the ring CFARs and speckle filters (the window, its
float64 statistic and the outputs) and about 120 for OS-CFAR (its ring order statistic).
Defaults (``tile=1024``, ``batch=4``, halo of a few pixels), measured on a 4096 x 4096
memmap: 0.56 GB peak RSS for CA-CFAR, 0.81 GB for OS-CFAR, whatever the scene size;
outputs written to a caller's array (e.g. a memmap) add nothing. The next batch of windows,
read ahead on a second thread, adds ``4 * batch * (tile + 2 * halo)^2`` bytes (17 MB at the
defaults).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterator
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import torch

from torchsar._checks import check_device, check_int
from torchsar.errors import OptionError
from torchsar.tiling.footprint import Operator, operator, to_batch
from torchsar.tiling.plan import Tile, batches, check_tile, plan_tiles
from torchsar.tiling.source import Scene, as_scene

__all__ = ["check_halo", "iter_tiles", "prepare", "scene_clutter_mean"]

DEFAULT_TILE = 1024
DEFAULT_BATCH = 4


def check_halo(halo: object, reach: int, name: str = "halo") -> int:
    """``halo`` (None: ``reach``) validated: an int ``>= reach``."""
    if halo is None:
        return reach
    h = check_int(halo, name, minimum=0)
    if h < reach:
        raise OptionError(
            f"{name}={h} is smaller than the operator's footprint reach ({reach} px): tiles "
            f"would not see every cell their core depends on; use {name} >= {reach} or None"
        )
    return h


def check_tile_fits(tile: tuple[int, int], op_min_side: int, name: str = "tile") -> None:
    """A tile smaller than the operator's footprint is refused (its window would hold more
    halo than core: wasteful, and a sign of a unit mistake)."""
    if min(tile) < op_min_side:
        raise OptionError(
            f"{name}={tile} is smaller than the operator's {op_min_side}x{op_min_side} "
            f"footprint; use {name} >= {op_min_side} (default {DEFAULT_TILE})"
        )


def scene_clutter_mean(
    scene: Scene, tiles: list[Tile], censor_pfa: float, iterations: int
) -> float:
    """AC-CFAR's global clutter mean ``mu`` over the whole scene (its step 1), streamed over
    the tile cores: one pass for the mean, one per re-estimation (the same rule as
    :func:`torchsar.cfar.ac.global_censor_threshold`)."""
    q = math.log(1.0 / censor_pfa)
    ratio_kept = 1.0 - censor_pfa * q / (1.0 - censor_pfa)
    limit = math.inf
    mu = 0.0
    for it in range(iterations + 1):
        total, count = 0.0, 0
        for t in tiles:
            x = scene.read(*t.core).astype(np.float64, copy=False)
            keep = x if it == 0 else x[x <= limit]
            total += float(keep.sum())
            count += keep.size
        mu = total / max(count, 1) / (1.0 if it == 0 else ratio_kept)
        limit = mu * q
    return mu


def _prepared(op: Operator, scene: Scene, tiles: list[Tile]) -> Operator:
    """``op`` with its scene-level statistics (AC: the clutter mean) filled in, unless the
    caller filled them already (:func:`prepare`)."""
    if op.name != "ac" or not tiles or "clutter_mean" in op.options:
        return op
    from torchsar._checks import check_probability

    pfa = check_probability(op.options.get("pfa", 1e-3), "pfa")
    cp = op.options.get("censor_pfa")
    p_c = pfa if cp is None else check_probability(cp, "censor_pfa")
    iterations = check_int(op.options.get("iterations", 3), "iterations", minimum=0)
    return op.with_options(clutter_mean=scene_clutter_mean(scene, tiles, p_c, iterations))


def prepare(scene: object, op: Operator, *, tile: int | tuple[int, int] = DEFAULT_TILE) -> Operator:
    """``op`` with its scene-level statistics computed once over the whole ``scene`` (AC:
    the clutter mean; other operators unchanged), so that tiles run separately
    (:func:`iter_tiles` with ``only``, other processes) share them.

    Examples:
        >>> x = np.ones((40, 40), np.float32)
        >>> op = prepare(x, operator("ac", guard=1, train=2), tile=16)
        >>> round(op.options["clutter_mean"], 4)  # the mean, corrected for censoring
        1.007
    """
    sc = as_scene(scene)
    return _prepared(op, sc, plan_tiles(sc.shape, check_tile(tile), 0))


def iter_tiles(
    scene: object,
    detector: str | Operator,
    *,
    tile: int | tuple[int, int] = DEFAULT_TILE,
    halo: int | None = None,
    batch: int = DEFAULT_BATCH,
    device: str | torch.device | None = None,
    only: Collection[tuple[int, int]] | None = None,
    **options: object,
) -> Iterator[tuple[Tile, dict[str, np.ndarray]]]:
    """Run a window operator over ``scene`` tile by tile; yield each tile and its core
    outputs (numpy, the core's shape).

    Tiles sharing a window shape run together, ``batch`` per call, on ``device`` (default:
    the CPU); the yield order is by window shape, then raster order. Every core equals the
    same pixels of the operator run on the whole scene (masks bit for bit, statistics to
    float rounding: the window sums are accumulated from a different origin). The next
    batch of windows is read on a second thread while this one runs (one more batch of
    windows in memory).

    Args:
        scene: 2-D intensity scene (see :func:`~torchsar.tiling.source.as_scene`).
        detector: a window CFAR or speckle-filter name, or an :class:`Operator`.
        tile: core side, or ``(rows, cols)``, >= the operator's footprint side.
        halo: pixels read around each core (default and minimum: the footprint reach).
        batch: windows per operator call (>= 1); the results do not depend on it.
        device: where the operator runs (None: CPU); outputs come back as numpy.
        only: run just the tiles of these indices ``(tile row, tile column)`` (None: all);
            scene-level statistics still cover the whole scene (:func:`prepare`).
        **options: the operator's options (``guard``, ``train``, ``pfa``, ``window``, ...).

    Raises:
        OptionError: bad ``tile``, ``halo``, ``batch``, ``device`` or operator option.
        InputTypeError, ShapeError, InputValueError, WindowSizeError: bad scene.
    """
    sc = as_scene(scene)
    op = detector if isinstance(detector, Operator) else operator(detector, **options)
    if isinstance(detector, Operator) and options:
        op = op.with_options(**options)
    size = check_tile(tile)
    check_tile_fits(size, op.min_side)
    hal = check_halo(halo, op.reach)
    batch = check_int(batch, "batch", minimum=1)
    dev = check_device(device)
    tiles = plan_tiles(sc.shape, size, hal, op.min_side)
    op = _prepared(op, sc, tiles)
    if only is not None:
        keep = {tuple(int(v) for v in i) for i in only}
        tiles = [t for t in tiles if t.index in keep]
    groups = list(batches(tiles, batch))
    staging = _Staging(dev)

    def read(k: int) -> tuple[torch.Tensor, object]:
        return staging.send([sc.read(*t.window) for t in groups[k]])

    # the next batch of windows is read (and moved to the device) on a second thread while
    # this one is processed and its outputs used: reading and decoding leave the critical path
    with ThreadPoolExecutor(1, thread_name_prefix="torchsar-read") as ahead:
        pending = ahead.submit(read, 0) if groups else None
        for k, group in enumerate(groups):
            x = staging.receive(*pending.result())
            pending = ahead.submit(read, k + 1) if k + 1 < len(groups) else None
            out = op.apply(x)
            for i, t in enumerate(group):
                yield t, {name: v[i, 0][t.inner].cpu().numpy() for name, v in out.items()}


def stack_into(windows: list[np.ndarray], out: torch.Tensor) -> torch.Tensor:
    """The same-shape windows copied into ``out`` ``(B, 1, H, W)`` (what
    :func:`~torchsar.tiling.footprint.to_batch` builds, without allocating); returns
    ``out``."""
    for k, w in enumerate(windows):
        out[k, 0].copy_(torch.from_numpy(w))
    return out


class _Staging:
    """How a batch of windows reaches the device. On the CPU (or any device but CUDA): a
    stacked tensor, moved. On CUDA: stacked into page-locked host memory and copied on a
    stream of its own (the reader thread's), so the copy of the next batch overlaps the
    kernels of this one; :meth:`receive` makes the computing stream wait for the copy and
    keeps the batch's memory until that stream is done with it."""

    def __init__(self, device: torch.device | None) -> None:
        self.cuda = device is not None and device.type == "cuda"
        self.device = device
        self.stream = torch.cuda.Stream(device) if self.cuda else None

    def send(self, windows: list[np.ndarray]) -> tuple[torch.Tensor, object]:
        """The batch on the device, and the event its copy records (``None``: ready)."""
        if not self.cuda:
            return to_batch(windows, self.device), None
        first = torch.from_numpy(windows[0])
        host = torch.empty((len(windows), 1, *first.shape), dtype=first.dtype, pin_memory=True)
        stack_into(windows, host)  # one host copy, straight into page-locked memory
        with torch.cuda.stream(self.stream):
            x = host.to(self.device, non_blocking=True)
            done = torch.cuda.Event()
            done.record(self.stream)
        return x, (done, host)

    def receive(self, x: torch.Tensor, copied: object) -> torch.Tensor:
        """``x``, safe to use on the current stream."""
        if copied is None:
            return x
        done, _host = copied  # the pinned source lives until here, past its copy's event
        current = torch.cuda.current_stream(self.device)
        current.wait_event(done)
        x.record_stream(current)  # its memory is not reused before this stream is done
        return x
