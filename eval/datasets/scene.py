"""``scene:FILE[?truth=CSV&chip=N]``: a whole scene (any file :func:`torchsar.io.open_scene`
reads: GeoTIFF, BigTIFF, COG, Sentinel-1 GRD measurement files, SICD) cut into ``N x N``
chips in raster order (default 2048; the last row and column of chips take the
remainder, so every pixel is in exactly one chip), each read as a window of the file, with
point ground truth from a CSV.

Ground truth: one row per target, its position ``row``, ``col`` (or xView3's
``detect_scene_row``, ``detect_scene_column``) in scene pixels, and optionally its extent
``height``, ``width`` in pixels (centred on the position; even sizes extend down / right,
as :func:`torchsar.simulate.scene_file.write_scene_file` plants them; 1 x 1 without). A
``scene_id`` column keeps the rows of this scene (the file's stem). A target belongs to
the chip holding its position; the part of its extent that reaches into a neighbouring
chip is an ignore region there. Without ``truth`` the scene has no targets (false alarms
only).

Saved point predictions in scene coordinates (``torchsar-eval detect``'s
``detections.csv``: ``scene_id``, ``detect_scene_row``, ``detect_scene_column``) are put
in the chip holding each point, in chip coordinates (:meth:`SceneDataset.locate_points`),
so a whole-scene detection table is scored with ``--predictions NAME=FILE`` and, for point
ground truth, ``--match distance --max-distance 3px``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from torchsar.io import open_scene
from torchsar_eval.datasets.base import FileDataset, make_item
from torchsar_eval.datasets.spec import DEFAULT_MAX_PIXELS, DatasetSpec
from torchsar_eval.errors import EvalError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["SCENE_OPTIONS", "SceneDataset", "scene_chips"]

SCENE_OPTIONS = ("truth", "chip", "type", "spacing", "max_pixels")
DEFAULT_CHIP = 2048

_ROW = ("row", "detect_scene_row")
_COL = ("col", "detect_scene_column")


def scene_chips(shape: tuple[int, int], chip: int) -> list[tuple[int, int, int, int]]:
    """``(r0, c0, r1, c1)`` chips of at most ``chip x chip`` covering the scene, raster order.

    Examples:
        >>> scene_chips((5, 3), 4)
        [(0, 0, 4, 3), (4, 0, 5, 3)]
    """
    h, w = shape
    return [
        (r, c, min(r + chip, h), min(c + chip, w))
        for r in range(0, h, chip)
        for c in range(0, w, chip)
    ]


def _column(df: pd.DataFrame, names: tuple[str, ...], path: Path) -> np.ndarray:
    import pandas as pd  # here, not at import: workers load datasets without pandas

    for n in names:
        if n in df.columns:
            values = pd.to_numeric(df[n], errors="coerce").to_numpy(np.float64)
            bad = ~np.isfinite(values) | (values != np.round(values))
            if bad.any():
                k = int(np.flatnonzero(bad)[0])
                raise EvalError(
                    f"truth {path}: row {k + 2}: {n} {df[n].iloc[k]!r} is not a whole pixel index"
                )
            return values.astype(np.int64)
    raise EvalError(
        f"truth {path} has no column {' or '.join(names)} "
        f"(columns: {', '.join(map(str, df.columns))})"
    )


def read_truth(path: Path, scene_id: str, shape: tuple[int, int]) -> pd.DataFrame:
    """The targets of one scene: ``row``, ``col``, ``height``, ``width`` (int64)."""
    import pandas as pd  # here, not at import: workers load datasets without pandas

    try:
        df = pd.read_csv(path, dtype={"scene_id": str})
    except (OSError, UnicodeDecodeError, pd.errors.ParserError) as exc:
        raise EvalError(f"truth {path} is not a readable CSV file ({exc})") from None
    except pd.errors.EmptyDataError:
        raise EvalError(f"truth {path} is empty (expected a header row,col)") from None
    if "scene_id" in df.columns:
        df = df[df["scene_id"] == scene_id].reset_index(drop=True)
    out = pd.DataFrame({"row": _column(df, _ROW, path), "col": _column(df, _COL, path)})
    for side in ("height", "width"):
        out[side] = _column(df, (side,), path) if side in df.columns else 1
        if (out[side] < 1).any():
            raise EvalError(f"truth {path}: {side} must be >= 1 pixel")
    h, w = shape
    outside = (out["row"] < 0) | (out["row"] >= h) | (out["col"] < 0) | (out["col"] >= w)
    if outside.any():
        k = int(np.flatnonzero(outside.to_numpy())[0])
        raise EvalError(
            f"truth {path}: target ({out['row'][k]}, {out['col'][k]}) lies outside "
            f"the {h}x{w} scene"
        )
    return out


class SceneDataset(FileDataset):
    """Chips of one scene file with point ground truth (see the module docstring)."""

    scheme = "scene"

    def __init__(
        self,
        path: str | Path,
        *,
        truth: str | Path | None = None,
        chip: int = DEFAULT_CHIP,
        sample_type: str | None = None,
        spacing: tuple[float, float] | None = None,
        max_pixels: int = DEFAULT_MAX_PIXELS,
        limit: int | None = None,
    ) -> None:
        if not Path(path).is_file():
            raise EvalError(f"scene {path} does not exist or is not a file")
        with open_scene(path) as reader:
            shape, found, file_spacing = reader.shape, reader.sample_type, reader.pixel_spacing
        sample_type = sample_type or found
        if sample_type is None:
            raise EvalError(
                f"scene {path} does not say what its samples are: declare "
                "?type=amplitude|intensity|db|complex"
            )
        if chip * chip > max_pixels:
            raise EvalError(
                f"scene option chip={chip}: {chip * chip:,} pixels per chip, over "
                f"max_pixels={max_pixels:,}"
            )
        super().__init__(
            path, sample_type=sample_type, spacing=spacing or file_spacing, max_pixels=max_pixels
        )
        self.scene_id = self.root.stem
        self.shape = (int(shape[0]), int(shape[1]))
        self.items = scene_chips(self.shape, chip)
        self.truth_path = None if truth is None else Path(truth)
        if self.truth_path is None:
            import pandas as pd  # here, not at import: workers load datasets without pandas

            self.targets = pd.DataFrame(
                {c: pd.Series(dtype="int64") for c in ("row", "col", "height", "width")}
            )
        else:
            if not self.truth_path.is_file():
                raise EvalError(f"truth {self.truth_path} does not exist or is not a file")
            self.targets = read_truth(self.truth_path, self.scene_id, self.shape)
            self.shared_files = [self.truth_path]
        self.chip = chip
        self.options.update(
            chip=chip, truth=None if truth is None else str(truth), targets=len(self.targets)
        )
        self.limit(limit)
        self.options["instances"] = "points"

    def item_files(self, i: int) -> list[Path]:
        return [self.root]

    def _name(self, i: int) -> str:
        r0, c0 = self.items[i][:2]
        return f"{self.scene_id}@{r0},{c0}"

    def item_key(self, i: int) -> dict:
        return {"name": self._name(i), "path": str(self.root)}

    def _chip_of(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """The item holding each scene pixel (-1 outside the scene or past ``limit``)."""
        h, w = self.shape
        per_row = -(-w // self.chip)
        inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        k = (rows // self.chip) * per_row + cols // self.chip
        return np.where(inside & (k < len(self.items)), k, -1)

    def locate_points(self, refs: np.ndarray, points: np.ndarray, what: str) -> tuple:
        """Items and chip-coordinate offsets of point predictions in scene coordinates.

        Args:
            refs: each row's scene (its ``scene_id``: this scene's file stem or name).
            points: ``(N, 2)`` scene ``(row, col)``.
            what: names the predictions in errors.

        Returns:
            ``(items, offsets)``: the item of each row and the ``(r0, c0)`` to subtract.

        Raises:
            EvalError: a row naming another scene, or a point outside the scene's chips.
        """
        names = {self.scene_id, self.root.name}
        other = [r for r in dict.fromkeys(refs.tolist()) if str(r) not in names]
        if other:
            raise EvalError(
                f"{what}: rows of scene {other[0]!r}, but the dataset is scene {self.scene_id!r}"
            )
        pix = np.floor(points + 0.5).astype(np.int64)  # the pixel whose centre is nearest
        items = self._chip_of(pix[:, 0], pix[:, 1])
        if (items < 0).any():
            k = int(np.flatnonzero(items < 0)[0])
            raise EvalError(
                f"{what}: point {points[k].tolist()} lies outside the "
                f"{self.shape[0]}x{self.shape[1]} scene's chips"
            )
        corners = np.array([self.items[i][:2] for i in range(len(self.items))], np.float64)
        return items, corners[items].reshape(-1, 2)

    def _truth(self, i: int) -> tuple[np.ndarray, np.ndarray, list]:
        """Instances (targets whose position is in the chip) and ignore pixels (the parts
        of other targets' extents reaching into it), and the instances' boxes."""
        r0, c0, r1, c1 = self.items[i]
        shape = (r1 - r0, c1 - c0)
        inst = np.zeros(shape, np.int32)
        ignore = np.zeros(shape, bool)
        t = self.targets
        top = t["row"] - (t["height"] - 1) // 2
        left = t["col"] - (t["width"] - 1) // 2
        near = (top < r1) & (top + t["height"] > r0) & (left < c1) & (left + t["width"] > c0)
        boxes = []
        for k in np.flatnonzero(near.to_numpy()):
            rs, cs = max(top[k], r0) - r0, max(left[k], c0) - c0
            re = min(top[k] + t["height"][k], r1) - r0
            ce = min(left[k] + t["width"][k], c1) - c0
            if r0 <= t["row"][k] < r1 and c0 <= t["col"][k] < c1:
                boxes.append((int(rs), int(cs), int(re), int(ce)))
                inst[rs:re, cs:ce] = len(boxes)
            else:
                ignore[rs:re, cs:ce] = True
        ignore &= inst == 0
        return inst, ignore, boxes

    def _meta(self, i: int) -> dict:
        meta = self.base_meta(self._name(i), self.root, None)
        meta.update(region=self.items[i], scene_id=self.scene_id)
        return meta

    def load_truth(self, i: int) -> dict:
        """The chip's ground truth without reading its pixels (zeros of its shape)."""
        inst, ignore, boxes = self._truth(i)
        return make_item(np.zeros(inst.shape, np.float32), inst, ignore, self._meta(i), boxes)

    def load(self, i: int) -> dict:
        r0, c0, r1, c1 = self.items[i]
        with open_scene(self.root) as reader:
            samples = reader[r0:r1, c0:c1]
        inst, ignore, boxes = self._truth(i)
        return make_item(self.intensity(samples, self.root), inst, ignore, self._meta(i), boxes)


def scene_from_spec(spec: DatasetSpec, limit: int | None) -> SceneDataset:
    """``scene:FILE?truth=CSV&chip=N&type=...&spacing=...&max_pixels=N``."""
    spec.check_keys(SCENE_OPTIONS)
    return SceneDataset(
        spec.path,
        truth=spec.options.get("truth"),
        chip=spec.positive_int("chip", DEFAULT_CHIP),
        sample_type=spec.sample_type(None),
        spacing=spec.spacing(),
        max_pixels=spec.max_pixels(),
        limit=limit,
    )
