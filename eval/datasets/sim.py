"""``sim-chips`` and ``sim-scenes``: simulated data, item ``i`` generated on demand.

Item ``i`` is ``torchsar.simulate.chips(1, seed=seed, start=i)[0]`` (or ``scenes``), which
equals item ``i`` of the batch generation, so items do not depend on access order and the
dataset holds nothing in memory.
"""

from __future__ import annotations

from torch.utils.data import Dataset

import torchsar as ts
from torchsar_eval.errors import EvalError

__all__ = ["DEFAULT_N", "SimDataset"]

DEFAULT_N = {"sim-chips": 64, "sim-scenes": 4}


class SimDataset(Dataset):
    """Simulated chips or scenes (seeded); every item carries the contract's meta keys."""

    def __init__(self, kind: str, n: int, seed: int, **options: object) -> None:
        if n < 0:
            raise EvalError(f"n must be >= 0, got {n}")
        self.make = ts.simulate.chips if kind == "sim-chips" else ts.simulate.scenes
        self.name, self.n, self.seed, self.kwargs = kind, n, seed, options
        self.options = {
            "n": n,
            "seed": seed,
            **options,
            "sample_type": "intensity",
            "instances": "simulated",
            "gt": "mask",
        }

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, i: int) -> dict:
        if not 0 <= i < self.n:
            raise IndexError(f"item {i} out of range for {self.n} items")
        item = self.make(1, seed=self.seed, start=i, **self.kwargs)[0]
        meta = item["meta"]
        item["meta"] = {
            "name": f"{self.name}/{i}",
            **meta,
            "pixel_spacing": (meta["pixel_m"], meta["pixel_m"]),
            "gt": "mask",
            "class": None,
            "sample_type": "intensity",
        }
        return item

    def item_key(self, i: int) -> dict:
        """The name of item ``i`` (as in its meta)."""
        return {"name": f"{self.name}/{i}"}

    def manifest(self) -> dict:
        """Simulated data have no files: the manifest is the generator and its options."""
        return {"generator": f"torchsar.simulate.{self.make.__name__}", **self.options}
