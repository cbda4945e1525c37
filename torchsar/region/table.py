"""The per-region table: one row per grown region of one image, in growth order."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["RegionRow", "RegionTable"]

REASONS = ("", "below_k", "few_background", "too_large", "too_small")


@dataclass(frozen=True)
class RegionRow:
    """One grown region. ``reason`` is ``""`` for an accepted region, else one of
    ``"below_k"`` (statistic <= k), ``"few_background"`` (censored ring smaller than
    ``min_background``), ``"too_large"`` (more than ``max_size`` pixels or than
    ``max_fraction`` of the image), ``"too_small"``
    (passed the test but its object has fewer than ``min_size`` pixels). Untested quantities
    are NaN."""

    seed: tuple[int, int]
    size: int
    mu_t: float
    mu_c: float
    sigma_c: float
    n_background: int
    statistic: float
    accepted: bool
    reason: str
    label: int = 0


@dataclass
class RegionTable:
    """The regions of one image, in the order they were grown (brightest seed first)."""

    rows: list[RegionRow] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.rows)

    def column(self, name: str) -> np.ndarray:
        """One column as a numpy array (e.g. ``table.column("statistic")``)."""
        return np.array([getattr(r, name) for r in self.rows])

    def to_frame(self):  # -> pandas.DataFrame (pandas imported lazily)
        """The table as a pandas DataFrame, one row per region."""
        import pandas as pd

        cols = RegionRow.__dataclass_fields__
        return pd.DataFrame([{c: getattr(r, c) for c in cols} for r in self.rows], columns=cols)
