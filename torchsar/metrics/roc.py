"""ROC accumulation over a fixed threshold grid, additive across batches and shards.

Pixel level: histograms of the detector statistic over target and clutter pixels on a fine
grid; ``Pd(t)`` and ``Pfa(t)`` for ``statistic > t`` come from suffix sums, so one pass of a
detector gives its whole pixel ROC with memory independent of the dataset size. Object
level: the object counts of :mod:`torchsar.metrics.detection` at a coarser grid (connected
components are relabelled per threshold). Accumulators with the same grids add up with ``+``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor

from torchsar.metrics.detection import ObjectCounts, object_counts

__all__ = ["RocAccumulator", "default_object_grid", "default_pixel_grid", "merged_grid"]


def default_pixel_grid(points_per_decade: int = 40) -> Tensor:
    """Symmetric log grid ``-1e6 .. -1e-3, 0, 1e-3 .. 1e6`` (float64): covers ratio and
    z-score statistics alike."""
    pos = torch.logspace(-3, 6, 9 * points_per_decade + 1, dtype=torch.float64)
    return torch.cat([-pos.flip(0), torch.zeros(1, dtype=torch.float64), pos])


def default_object_grid(threshold: float, n: int = 25) -> Tensor:
    """Object-level thresholds around a design threshold: ``threshold x [0.1 .. 10]``
    (log-spaced) for positive thresholds, ``threshold + [-5 .. 5]`` otherwise."""
    if threshold > 0:
        return threshold * torch.logspace(-1, 1, n, dtype=torch.float64)
    return threshold + torch.linspace(-5, 5, n, dtype=torch.float64)


def _exceedances(values: Tensor, grid: Tensor) -> Tensor:
    """``out[k] = #(values > grid[k])`` via one bucketize and a suffix sum."""
    idx = torch.bucketize(values.to(torch.float64).flatten(), grid.to(values.device))
    hist = torch.bincount(idx, minlength=grid.numel() + 1).cpu()
    return hist.flip(0).cumsum(0).flip(0)[1:]


@dataclass
class RocAccumulator:
    """Accumulates pixel and object ROC counts for one detector on one dataset.

    Args:
        pixel_grid: thresholds of the pixel ROC (sorted ascending).
        object_grid: thresholds of the object ROC (sorted ascending).
        connectivity: component connectivity of the object counts.
    """

    pixel_grid: Tensor = field(default_factory=default_pixel_grid)
    object_grid: Tensor = field(default_factory=lambda: default_object_grid(1.0))
    connectivity: int = 2
    target_hits: Tensor = field(init=False)
    clutter_hits: Tensor = field(init=False)
    targets: int = field(init=False, default=0)
    clutter: int = field(init=False, default=0)
    objects: list[ObjectCounts] = field(init=False)

    def __post_init__(self) -> None:
        self.pixel_grid = self.pixel_grid.to(torch.float64).cpu()
        self.object_grid = self.object_grid.to(torch.float64).cpu()
        self.target_hits = torch.zeros(self.pixel_grid.numel(), dtype=torch.int64)
        self.clutter_hits = torch.zeros(self.pixel_grid.numel(), dtype=torch.int64)
        self.objects = [ObjectCounts() for _ in range(self.object_grid.numel())]

    def update(
        self,
        statistic: Tensor,
        target: Tensor,
        instances: Tensor,
        ignore: Tensor | None = None,
    ) -> None:
        """Add a batch: ``statistic`` float, ``target`` bool, ``instances`` int, same shape."""
        care = torch.ones_like(target) if ignore is None else ~ignore
        tgt, clu = target & care, ~target & care
        self.target_hits += _exceedances(statistic[tgt], self.pixel_grid)
        self.clutter_hits += _exceedances(statistic[clu], self.pixel_grid)
        self.targets += int(tgt.sum())
        self.clutter += int(clu.sum())
        for k, t in enumerate(self.object_grid.tolist()):
            self.objects[k] = self.objects[k] + object_counts(
                statistic > t, instances, ignore, connectivity=self.connectivity
            )

    def __add__(self, other: RocAccumulator) -> RocAccumulator:
        if not (
            torch.equal(self.pixel_grid, other.pixel_grid)
            and torch.equal(self.object_grid, other.object_grid)
        ):
            raise ValueError("cannot add RocAccumulators with different threshold grids")
        out = RocAccumulator(self.pixel_grid, self.object_grid, self.connectivity)
        out.target_hits = self.target_hits + other.target_hits
        out.clutter_hits = self.clutter_hits + other.clutter_hits
        out.targets = self.targets + other.targets
        out.clutter = self.clutter + other.clutter
        out.objects = [a + b for a, b in zip(self.objects, other.objects, strict=True)]
        return out

    def pixel_curve(self) -> dict[str, np.ndarray]:
        """``threshold``, ``pd_pixel``, ``pfa_pixel`` arrays over the pixel grid."""
        return {
            "threshold": self.pixel_grid.numpy(),
            "pd_pixel": self.target_hits.numpy() / max(self.targets, 1),
            "pfa_pixel": self.clutter_hits.numpy() / max(self.clutter, 1),
        }

    def object_curve(self) -> dict[str, np.ndarray]:
        """Pixel and object scores at every object-grid threshold."""
        t = self.object_grid
        idx = torch.searchsorted(self.pixel_grid, t).clamp(max=self.pixel_grid.numel() - 1)
        exact = torch.isclose(self.pixel_grid[idx], t, rtol=1e-12, atol=0)
        if not bool(exact.all()):
            raise ValueError("object_grid thresholds must be points of pixel_grid")
        return {
            "threshold": t.numpy(),
            "pd_pixel": self.target_hits[idx].numpy() / max(self.targets, 1),
            "pfa_pixel": self.clutter_hits[idx].numpy() / max(self.clutter, 1),
            "pd_object": np.array([o.pd for o in self.objects]),
            "false_alarms_per_image": np.array([o.false_alarms_per_image for o in self.objects]),
        }


def merged_grid(pixel_grid: Tensor, object_grid: Tensor) -> Tensor:
    """The pixel grid with the object thresholds inserted (sorted, unique)."""
    return torch.unique(torch.cat([pixel_grid.to(torch.float64), object_grid.to(torch.float64)]))
