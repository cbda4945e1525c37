"""Pixel ROC accumulation over a fixed threshold grid, additive across batches and shards.

Histograms of the detector statistic over target and clutter pixels on a fine grid;
``Pd(t)`` and ``Pfa(t)`` for ``statistic > t`` come from suffix sums, so one pass of a
detector gives its whole pixel ROC with memory independent of the dataset size. Accumulators
with the same grid add up with ``+``. (Object-level curves come from
:class:`~torchsar.metrics.ObjectState`: objects ranked by score, not images re-labelled per
threshold.)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor

from torchsar import _jit
from torchsar._checks import InputTypeError, InputValueError, check_same_shape, has_nan
from torchsar.metrics.counts import PixelCounts, pixel_counts
from torchsar.metrics.log_bins import LogGrid

__all__ = ["RocAccumulator", "default_pixel_grid"]


_NAN = "statistic must not contain NaN (it has no place on a ROC)"


def default_pixel_grid(points_per_decade: int = 40) -> Tensor:
    """Symmetric log grid ``-1e6 .. -1e-3, 0, 1e-3 .. 1e6`` (float64): covers ratio and
    z-score statistics alike."""
    return LogGrid(points_per_decade).grid


def _flat(t: Tensor) -> np.ndarray:
    """A CPU tensor as a flat contiguous array (no copy when it is contiguous)."""
    return t.contiguous().view(-1).numpy()


def _exceedances(hist: Tensor) -> Tensor:
    """``out[k] = #(values > grid[k])`` from the bucket histogram (a suffix sum)."""
    return hist.flip(0).cumsum(0).flip(0)[1:]


@dataclass
class RocAccumulator:
    """Accumulates the pixel ROC counts of one detector on one dataset.

    Args:
        pixel_grid: thresholds of the pixel ROC (sorted ascending).
    """

    pixel_grid: Tensor = field(default_factory=default_pixel_grid)
    target_hits: Tensor = field(init=False)
    clutter_hits: Tensor = field(init=False)
    targets: int = field(init=False, default=0)
    clutter: int = field(init=False, default=0)

    def __post_init__(self) -> None:
        self.pixel_grid = self.pixel_grid.to(torch.float64).cpu()
        self.target_hits = torch.zeros(self.pixel_grid.numel(), dtype=torch.int64)
        self.clutter_hits = torch.zeros(self.pixel_grid.numel(), dtype=torch.int64)
        self._log_grid = LogGrid.matching(self.pixel_grid)
        self._starts: np.ndarray | None = None  # float32 bucket starts of the compiled kernel

    def update(
        self,
        statistic: Tensor,
        target: Tensor,
        ignore: Tensor | None = None,
        *,
        detected: Tensor | None = None,
    ) -> PixelCounts | None:
        """Add a batch: ``statistic`` float, ``target`` bool, optional ``ignore`` bool, all
        of one shape. With ``detected`` (a bool detection mask of that shape) also returns
        its :func:`~torchsar.metrics.pixel_counts` against ``target`` and ``ignore``, counted
        in the same pass over the pixels where it can be (float32 on the CPU).

        Example:
            >>> acc = RocAccumulator()
            >>> stat = torch.tensor([0.5, 2.0, 3.0]); tgt = torch.tensor([False, True, False])
            >>> c = acc.update(stat, tgt, detected=stat > 1.0)
            >>> (c.tp, c.fp, c.targets, c.clutter), acc.targets
            ((1, 1, 1, 2), 1)
        """
        if not isinstance(statistic, Tensor) or not statistic.is_floating_point():
            raise InputTypeError("statistic must be a floating torch.Tensor")
        for name, t in (("target", target), ("ignore", ignore), ("detected", detected)):
            if t is not None and (not isinstance(t, Tensor) or t.dtype != torch.bool):
                raise InputTypeError(f"{name} must be a bool tensor")
            if t is not None:
                check_same_shape(statistic, t, "statistic", name)
        one_pass = self._one_pass(statistic, target, ignore, detected)
        if one_pass is None:
            if has_nan(statistic):
                raise InputValueError(_NAN)
            hist = self._histogram(statistic, target, ignore)
            counts = None if detected is None else pixel_counts(detected, target, ignore=ignore)
        else:
            hist, counts = one_pass
        self.target_hits += _exceedances(hist[0])
        self.clutter_hits += _exceedances(hist[1])
        self.targets += int(hist[0].sum())
        self.clutter += int(hist[1].sum())
        return counts

    def _one_pass(
        self, values: Tensor, target: Tensor, ignore: Tensor | None, detected: Tensor | None
    ) -> tuple[Tensor, PixelCounts] | None:
        """The histogram and the detection mask's pixel counts in one compiled pass, for
        float32 batches the kernels take, with a mask; ``None`` otherwise. Raises on NaN
        before anything is added."""
        if detected is None or values.dtype != torch.float32 or not self._compiled_for(values):
            return None
        hist, c, nan = self._float32_pass(values, target, ignore, detected)
        if nan:
            raise InputValueError(_NAN)
        tp, det, targets, counted = (int(v) for v in c)
        return hist, PixelCounts(tp, det - tp, targets, counted - targets)

    def _compiled_for(self, values: Tensor) -> bool:
        """Whether :mod:`torchsar.metrics._kernels` histogram ``values`` (the default grid,
        a tensor the kernels take)."""
        return self._log_grid is not None and _jit.for_tensor(values.detach())

    def _float32_pass(
        self, values: Tensor, target: Tensor, ignore: Tensor | None, detected: Tensor | None
    ) -> tuple[Tensor, np.ndarray, bool]:
        """:func:`torchsar.metrics._kernels.float32_roc_pass` on a batch: histogram, pixel
        counts of ``detected`` (meaningless without one) and whether a value is NaN."""
        from torchsar.metrics import _kernels

        grid = self.pixel_grid.to(torch.float32).numpy()
        if self._starts is None:
            self._starts = _kernels.float32_starts(grid)
        tgt = _flat(target)
        ign = tgt if ignore is None else _flat(ignore)
        det = tgt if detected is None else _flat(detected)
        flat = _flat(values.detach())
        hist, counts, nan = _kernels.float32_roc_pass(flat, tgt, ign, ignore is not None, det,
                                                      grid, self._starts)  # fmt: skip
        return torch.from_numpy(hist), counts, nan

    def update_sparse(
        self, values: Tensor, target: Tensor, ignore: Tensor, targets: int, clutter: int
    ) -> None:
        """Add a batch whose statistic is ``-inf`` except at some pixels: their ``values``
        with their ``target`` / ``ignore`` flags (bool, same length), and the batch's
        counts of target and clutter pixels (``-inf`` exceeds no threshold, so only the
        listed pixels reach the histograms). Equal to :meth:`update` on the dense batch.

        Example:
            >>> a, b = RocAccumulator(), RocAccumulator()
            >>> stat = torch.full((6,), -torch.inf); stat[[1, 4]] = torch.tensor([2.0, 0.5])
            >>> tgt = torch.tensor([0, 1, 1, 0, 0, 0], dtype=torch.bool)
            >>> a.update(stat, tgt)
            >>> no = torch.zeros(2, dtype=torch.bool)
            >>> b.update_sparse(stat[[1, 4]], tgt[[1, 4]], no, targets=2, clutter=4)
            >>> [torch.equal(getattr(a, k), getattr(b, k)) for k in ("target_hits", "clutter_hits")]
            [True, True]
        """
        if has_nan(values):
            raise InputValueError(_NAN)
        hist = self._histogram(values, target, ignore)
        self.target_hits += _exceedances(hist[0])
        self.clutter_hits += _exceedances(hist[1])
        self.targets += int(targets)
        self.clutter += int(clutter)

    def _histogram(self, values: Tensor, target: Tensor, ignore: Tensor | None) -> Tensor:
        """``(3, grid + 1)`` int64 counts (CPU) of (class, bucket): class 0 target, 1
        clutter, 2 ignored; bucket ``b`` holds the values with ``grid[b - 1] < v <=
        grid[b]``, so ``v > grid[k]`` exactly when its bucket is above ``k``. On the CPU with
        the default grid one compiled pass (:mod:`torchsar.metrics._kernels`) gives the
        tensor code's counts without its intermediate tensors."""
        if self._compiled_for(values):
            return self._compiled_histogram(values, target, ignore)
        grid = self.pixel_grid.to(device=values.device, dtype=values.dtype)
        n = grid.numel() + 1
        bins = self._bins(values, grid)
        cls = (~target).long() if ignore is None else (~target).long().masked_fill_(ignore, 2)
        return torch.bincount(cls.mul_(n).add_(bins).view(-1), minlength=3 * n).cpu().view(3, n)

    def _compiled_histogram(self, values: Tensor, target: Tensor, ignore: Tensor | None) -> Tensor:
        if values.dtype == torch.float32:
            return self._float32_pass(values, target, ignore, None)[0]
        from torchsar.metrics import _kernels
        from torchsar.metrics.log_bins import _SURE

        lg = self._log_grid
        tgt = _flat(target)
        ign = tgt if ignore is None else _flat(ignore)
        hist = _kernels.log_grid_histogram(_flat(values.detach()), tgt, ign, ignore is not None,
                                           self.pixel_grid.numpy(), lg.m, float(lg.low),
                                           float(lg.ppd), _SURE)  # fmt: skip
        return torch.from_numpy(hist)

    def _bins(self, statistic: Tensor, grid: Tensor) -> Tensor:
        """``torch.bucketize(statistic, grid)``, by arithmetic when the grid is the default
        kind."""
        if self._log_grid is None:
            return torch.bucketize(statistic, grid)
        return self._log_grid.bucketize(statistic, grid)

    def __add__(self, other: RocAccumulator) -> RocAccumulator:
        if not torch.equal(self.pixel_grid, other.pixel_grid):
            raise ValueError("cannot add RocAccumulators with different threshold grids")
        out = RocAccumulator(self.pixel_grid)
        out.target_hits = self.target_hits + other.target_hits
        out.clutter_hits = self.clutter_hits + other.clutter_hits
        out.targets = self.targets + other.targets
        out.clutter = self.clutter + other.clutter
        return out

    def pixel_curve(self) -> dict[str, np.ndarray]:
        """``threshold``, ``pd_pixel``, ``pfa_pixel`` arrays over the pixel grid."""
        return {
            "threshold": self.pixel_grid.numpy(),
            "pd_pixel": self.target_hits.numpy() / max(self.targets, 1),
            "pfa_pixel": self.clutter_hits.numpy() / max(self.clutter, 1),
        }
