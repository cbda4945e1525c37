"""Scene-level objects: connected components of a tiled mask, merged across tile seams.

Each tile's core mask is labelled on its own (8-connected, or 4 with ``connectivity=1``);
per component only its aggregates are kept (area, coordinate sums, bounding box, best
score and its pixel) and the labels of the core's four edge lines. Components that touch
across a seam (the last row of one tile row and the first of the next, over the full scene
width, which also covers diagonal contacts at tile corners; the last and first columns of
neighbouring tiles within a tile row) are joined by union-find, and the aggregates of each
union reduce to one row. So an object straddling seams is one row, identical to the
component of the untiled mask, and no full-scene mask or label image is ever allocated:
memory is the per-component aggregates plus four edge lines per tile.

Rows: ``row``, ``col`` the centroid (mean pixel coordinates, float); ``peak_row``,
``peak_col`` the pixel of the highest score (ties: the first in raster order); ``score``
that score (the detector's statistic); ``area`` in pixels; ``row_min``, ``row_max``,
``col_min``, ``col_max`` the bounding box (inclusive). Sorted by score descending, then
peak position in raster order (a total order: peaks are distinct pixels).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from torchsar.errors import OptionError
from torchsar.tiling.plan import Tile

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["COLUMNS", "SeamMerger", "components_table"]

COLUMNS = (
    "row",
    "col",
    "peak_row",
    "peak_col",
    "score",
    "area",
    "row_min",
    "row_max",
    "col_min",
    "col_max",
)

_STRUCT = {1: ndimage.generate_binary_structure(2, 1), 2: np.ones((3, 3), dtype=bool)}


def _check_connectivity(connectivity: object) -> int:
    if connectivity not in (1, 2) or isinstance(connectivity, bool):
        raise OptionError(
            f"connectivity must be 1 (4-connected) or 2 (8-connected), got {connectivity!r}"
        )
    return int(connectivity)  # type: ignore[arg-type]


def _aggregates(lab: np.ndarray, n: int, score: np.ndarray, r0: int, c0: int, width: int):
    """Per-label (1..n) aggregates of one labelled core, in scene coordinates:
    ``(area, sum_r, sum_c, rmin, rmax, cmin, cmax, score, peak_flat)``."""
    rr, cc = np.nonzero(lab)
    ll = lab[rr, cc]
    rr, cc = rr + r0, cc + c0
    area = np.bincount(ll, minlength=n + 1)[1:]
    sum_r = np.bincount(ll, rr.astype(np.float64), minlength=n + 1)[1:]
    sum_c = np.bincount(ll, cc.astype(np.float64), minlength=n + 1)[1:]
    boxes = ndimage.find_objects(lab, max_label=n)
    rmin = np.array([b[0].start + r0 for b in boxes], dtype=np.int64)
    rmax = np.array([b[0].stop - 1 + r0 for b in boxes], dtype=np.int64)
    cmin = np.array([b[1].start + c0 for b in boxes], dtype=np.int64)
    cmax = np.array([b[1].stop - 1 + c0 for b in boxes], dtype=np.int64)
    flat = rr.astype(np.int64) * width + cc
    s = score[rr - r0, cc - c0].astype(np.float64)
    order = np.lexsort((flat, -s, ll))  # per label: best score, then raster order
    first = order[np.r_[True, ll[order][1:] != ll[order][:-1]]]
    return area, sum_r, sum_c, rmin, rmax, cmin, cmax, s[first], flat[first]


@dataclass
class SeamMerger:
    """Accumulates tile cores (mask and score) and merges components across seams.

    Feed every tile once with :meth:`add` (any order), then :meth:`table`.
    """

    shape: tuple[int, int]
    connectivity: int = 2
    _parts: list = field(default_factory=list)
    _edges: dict = field(default_factory=dict)
    _offsets: dict = field(default_factory=dict)
    _count: int = 0
    _merged: tuple | None = None

    def __post_init__(self) -> None:
        self.connectivity = _check_connectivity(self.connectivity)

    def add(self, tile: Tile, mask: np.ndarray, score: np.ndarray) -> None:
        """Label one core (``mask``, ``score`` of the core's shape) and keep its aggregates
        and edge lines (labels offset to be unique across tiles): :meth:`summarise`, then
        :meth:`merge`."""
        self.merge(self.summarise(tile, mask, score))

    def summarise(self, tile: Tile, mask: np.ndarray, score: np.ndarray) -> dict:
        """The compact record of one core: everything :meth:`merge` needs, and nothing of
        this merger's state (so it can be computed in another process, saved and merged
        later; merging records in a fixed tile order gives the same table whatever order
        they were computed in).

        Returns:
            ``{"index": (i, j) int64, "core": (r0, r1, c0, c1) int64, "n": components,
            "edges": four int32 lines (first row, last row, first column, last column) of
            local labels 1..n (0 background), "aggregates": nine per-component arrays}``,
            numpy arrays and ints only.

        Examples:
            >>> m = SeamMerger((2, 4))
            >>> t = Tile((0, 0), (slice(0, 2), slice(0, 4)), (slice(0, 2), slice(0, 4)))
            >>> rec = m.summarise(t, np.array([[1, 0, 0, 1], [1, 0, 0, 0]], bool), np.ones((2, 4)))
            >>> rec["n"], rec["edges"][2].tolist()
            (2, [1, 1])
        """
        lab, n = ndimage.label(mask, structure=_STRUCT[self.connectivity])
        (rows, cols) = tile.core
        r0, c0 = rows.start, cols.start
        lab32 = lab.astype(np.int32, copy=False)
        edges = tuple(
            np.ascontiguousarray(e) for e in (lab32[0], lab32[-1], lab32[:, 0], lab32[:, -1])
        )
        if n:
            parts = _aggregates(lab, n, score, r0, c0, self.shape[1])
        else:
            parts = tuple(np.zeros(0, np.float64 if k in (1, 2, 7) else np.int64) for k in range(9))
        return {
            "index": np.array(tile.index, np.int64),
            "core": np.array([rows.start, rows.stop, cols.start, cols.stop], np.int64),
            "n": int(n),
            "edges": edges,
            "aggregates": tuple(parts),
        }

    def merge(self, record: dict) -> None:
        """Take one core's record (:meth:`summarise`); each tile once, in any order (a fixed
        order gives bit-identical tables)."""
        index = tuple(int(v) for v in record["index"])
        n = int(record["n"])
        self._offsets[index] = (self._count, n)
        self._merged = None
        self._edges[index] = tuple(
            np.where(e > 0, e.astype(np.int64) + self._count, 0) for e in record["edges"]
        )
        if n:
            self._parts.append(tuple(record["aggregates"]))
        self._count += n

    def _pairs(self) -> np.ndarray:
        """``(k, 2)`` global ids touching across seams."""
        shifts = (-1, 0, 1) if self.connectivity == 2 else (0,)
        pairs: list[np.ndarray] = []

        def touch(a: np.ndarray, b: np.ndarray) -> None:
            n = a.size
            for s in shifts:
                x = a[max(0, -s) : n - max(0, s)]
                y = b[max(0, s) : n - max(0, -s)]
                keep = (x > 0) & (y > 0)
                if keep.any():
                    pairs.append(np.stack([x[keep], y[keep]], 1))

        rows = sorted({i for i, _ in self._edges})
        cols = sorted({j for _, j in self._edges})
        for i in rows:
            for j in cols[:-1]:  # vertical seams inside tile row i
                touch(self._edges[(i, j)][3], self._edges[(i, j + 1)][2])
        for i in rows[:-1]:  # horizontal seams over the full scene width
            above = np.concatenate([self._edges[(i, j)][1] for j in cols])
            below = np.concatenate([self._edges[(i + 1, j)][0] for j in cols])
            touch(above, below)
        return np.concatenate(pairs) if pairs else np.zeros((0, 2), np.int64)

    def _merge(self) -> tuple[int, np.ndarray, tuple[np.ndarray, ...]]:
        """``(m, root, parts)``: the number of merged objects, each component's object and
        the concatenated per-component aggregates (cached until the next :meth:`add`)."""
        if self._merged is None:
            parts = tuple(np.concatenate(a) for a in zip(*self._parts, strict=True))
            n = self._count
            p = self._pairs() - 1
            graph = coo_matrix((np.ones(len(p)), (p[:, 0], p[:, 1])), shape=(n, n))
            m, root = connected_components(graph, directed=False)
            self._merged = (m, root, parts)
        return self._merged

    def small(self, tile: Tile, min_size: int) -> np.ndarray:
        """Bool per core label ``0..n`` of ``tile``: whether its merged object has fewer
        than ``min_size`` pixels (label 0, the background, is False)."""
        offset, n = self._offsets[tile.index]
        out = np.zeros(n + 1, dtype=bool)
        if n:
            m, root, parts = self._merge()
            area = np.bincount(root, parts[0], minlength=m)
            out[1:] = area[root[offset : offset + n]] < min_size
        return out

    def relabel(self, tile: Tile, mask: np.ndarray) -> np.ndarray:
        """The core labels of :meth:`add` again for the same ``mask``."""
        return ndimage.label(mask, structure=_STRUCT[self.connectivity])[0]

    def table(self) -> pd.DataFrame:
        """One row per merged object (see the module docstring)."""
        import pandas as pd  # here, not at import: torchsar loads without pandas

        if self._count == 0:
            return pd.DataFrame({c: pd.Series(dtype=_dtype(c)) for c in COLUMNS})
        m, root, parts = self._merge()
        area, sr, sc, rmin, rmax, cmin, cmax, score, peak = parts
        out = {
            "area": np.bincount(root, area, minlength=m).astype(np.int64),
            "row": np.bincount(root, sr, minlength=m),
            "col": np.bincount(root, sc, minlength=m),
            "row_min": _reduce(np.minimum, root, rmin, m),
            "row_max": _reduce(np.maximum, root, rmax, m),
            "col_min": _reduce(np.minimum, root, cmin, m),
            "col_max": _reduce(np.maximum, root, cmax, m),
        }
        out["row"] /= out["area"]
        out["col"] /= out["area"]
        order = np.lexsort((peak, -score, root))
        first = order[np.r_[True, root[order][1:] != root[order][:-1]]]
        out["score"] = score[first]
        out["peak_row"], out["peak_col"] = np.divmod(peak[first], self.shape[1])
        df = pd.DataFrame({c: out[c] for c in COLUMNS})
        return _sorted(df)


def _reduce(op: np.ufunc, root: np.ndarray, v: np.ndarray, m: int) -> np.ndarray:
    info = np.iinfo(v.dtype)
    out = np.full(m, info.max if op is np.minimum else info.min, dtype=v.dtype)
    op.at(out, root, v)
    return out


def _dtype(column: str) -> str:
    return "float64" if column in ("row", "col", "score") else "int64"


def _sorted(df: pd.DataFrame) -> pd.DataFrame:
    return df.sort_values(
        ["score", "peak_row", "peak_col"], ascending=[False, True, True], kind="mergesort"
    ).reset_index(drop=True)


def components_table(mask: np.ndarray, score: np.ndarray, connectivity: int = 2) -> pd.DataFrame:
    """The object table of a whole in-memory mask (one tile covering the image): the same
    rows :class:`SeamMerger` gives for any tiling of it.

    Examples:
        >>> m = np.array([[1, 1, 0], [0, 0, 1]], bool)
        >>> s = np.array([[2.0, 5.0, 0.0], [0.0, 0.0, 3.0]])
        >>> t = components_table(m, s)
        >>> t.loc[0, ["peak_row", "peak_col", "area", "row_max"]].tolist(), float(t.score[0])
        ([0, 1, 3, 1], 5.0)
    """
    h, w = mask.shape
    merger = SeamMerger((h, w), connectivity)
    merger.add(Tile((0, 0), (slice(0, h), slice(0, w)), (slice(0, h), slice(0, w))), mask, score)
    return merger.table()
