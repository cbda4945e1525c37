"""Saved predictions as a folder of per-image masks: ``<image>.png``, ``.tif``/``.tiff`` or
``.npy`` named after the image (its name, file name or stem).

- An integer map holds instance ids (0 = none); ``<image>.scores.json`` may give each id's
  score (``{"1": 0.93, "2": 0.41}``; default 1). The instances are scored as they are.
- A float map is a per-pixel score (e.g. a segmentation network's probabilities): it goes
  through the discrimination stage like a CFAR's statistic, at the declared threshold.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from torchsar.detection import detection_from
from torchsar.io.errors import FileFormatError
from torchsar.io.raster import check_regular_file
from torchsar.objects import Objects
from torchsar_eval.errors import EvalError

__all__ = ["MASK_EXTS", "MaskFolder"]

MASK_EXTS = (".png", ".tif", ".tiff", ".npy")


def _stem(path: Path) -> str:
    return path.name[: -len(path.suffix)] if path.suffix else path.name


class MaskFolder:
    """The mask files of a folder (see the module docstring)."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        files = sorted(
            f for f in self.root.rglob("*") if f.is_file() and f.suffix.lower() in MASK_EXTS
        )
        if not files:
            raise EvalError(f"predictions {root}: no mask files ({', '.join(MASK_EXTS)})")
        self.files = files
        self.refs = np.array(
            [
                str(f.relative_to(self.root).with_suffix(""))
                if f.parent != (self.root)
                else _stem(f)
                for f in files
            ],
            dtype=object,
        )
        seen: dict[str, Path] = {}
        for f, ref in zip(files, self.refs.tolist(), strict=True):
            if ref in seen:
                raise EvalError(
                    f"predictions {root}: {seen[ref].name} and {f.name} are both "
                    f"the mask of image {ref}; keep one"
                )
            seen[ref] = f
        self.score = np.ones(len(files))

    def __len__(self) -> int:
        return len(self.files)

    def _read(self, path: Path, shape: tuple[int, int]) -> np.ndarray:
        if path.suffix.lower() == ".npy":  # its header's shape checked before it is read
            try:
                arr = np.load(path, allow_pickle=False, mmap_mode="r")
            except (ValueError, OSError) as exc:  # a header the bytes do not back
                raise EvalError(f"predictions {path}: not a readable .npy mask ({exc})") from None
            if int(np.prod(arr.shape)) != shape[0] * shape[1]:
                raise EvalError(f"predictions {path}: a {arr.shape} mask for an image of {shape}")
            arr = np.array(arr)
        else:
            # the raster readers only for masks saved as image files
            from torchsar.io import read_raster

            arr = np.asarray(read_raster(path))
        arr = np.squeeze(arr)
        if arr.shape != shape:
            raise EvalError(f"predictions {path}: a {arr.shape} mask for an image of {shape}")
        if arr.dtype == bool:
            arr = arr.astype(np.int32)
        if arr.dtype.kind not in "iuf":
            raise EvalError(
                f"predictions {path}: a mask of {arr.dtype} values; expected "
                "integer instance ids or float scores"
            )
        if arr.dtype.kind == "f" and not np.isfinite(arr).all():
            raise EvalError(f"predictions {path}: a score map holding NaN or inf")
        if arr.dtype.kind == "u" and arr.size and int(arr.max()) > np.iinfo(np.int64).max:
            raise EvalError(f"predictions {path}: an instance id past 2**63")
        return arr.astype(np.int64) if arr.dtype.kind in "iu" else arr

    def _scores(self, path: Path, ids: np.ndarray) -> dict[int, float]:
        side = path.with_name(_stem(path) + ".scores.json")
        if not side.is_file():
            return {}
        try:
            check_regular_file(side)
            raw = json.loads(side.read_text())
            return {int(k): float(v) for k, v in raw.items()}
        except (
            ValueError,
            TypeError,
            AttributeError,
            RecursionError,
            OSError,
            FileFormatError,
        ) as exc:
            raise EvalError(
                f'predictions {side}: expected {{"id": score}} ({str(exc)[:200]})'
            ) from None

    def batch(self, rows: list[np.ndarray], shape: tuple[int, int, int, int], threshold):
        """The objects (integer maps) or the detection (score maps) of a batch; ``rows``:
        each image's files (at most one); images without a file have no prediction."""
        b, c, h, w = shape
        maps = [self._read(self.files[r[0]], (h, w)) if r.size else None for r in rows]
        kinds = {np.issubdtype(m.dtype, np.floating) for m in maps if m is not None}
        if kinds == {True}:
            if threshold is None:
                raise EvalError(
                    f"predictions {self.root} are score maps: declare their "
                    "operating threshold (threshold=...)"
                )
            stat = np.full((b, c, h, w), -np.inf)
            for k, m in enumerate(maps):
                if m is not None:
                    stat[k, 0] = m
            return detection_from(torch.from_numpy(stat), float(threshold))
        if len(kinds) > 1:
            raise EvalError(f"predictions {self.root} mix integer id maps and float score maps")
        labels = np.zeros((b * c, h, w), np.int64)
        score = np.zeros((b * c, h, w))
        for k, m in enumerate(maps):
            if m is None:
                continue
            if (m < 0).any():
                raise EvalError(f"predictions {self.files[rows[k][0]]}: negative instance ids")
            # ids relabelled 1..K in order: an id of 2**31 costs no table of 2**31 entries
            ids = np.union1d([0], np.unique(m))
            dense = np.searchsorted(ids, m)
            labels[k * c] = dense
            table = self._scores(self.files[rows[k][0]], ids)
            lut = np.array([1.0] + [table.get(int(i), 1.0) for i in ids[1:].tolist()])
            score[k * c] = lut[dense]
        return Objects.from_labels(labels, score, threshold=None)
