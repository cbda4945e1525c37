"""What every file-backed dataset shares: the item contract, error wrapping, declared
scaling (with the ``display`` warning), options and the manifest."""

from __future__ import annotations

import os
import warnings
from abc import ABC, abstractmethod
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from torchsar.errors import TorchSARError
from torchsar.io import FileFormatError, raster_shape, to_intensity
from torchsar_eval.datasets.manifest import file_manifest
from torchsar_eval.datasets.semantics import boxes_of, check_instance_counts
from torchsar_eval.errors import EvalError

__all__ = [
    "SANITY_ITEMS",
    "BadItemError",
    "DisplayScalingWarning",
    "FileDataset",
    "make_item",
    "require_dir",
    "walk_files",
]

SANITY_ITEMS = 16  # items read at construction for the split/merged instance check


class BadItemError(EvalError):
    """One item of a dataset cannot be read; ``path`` names the file (runners may skip it)."""

    def __init__(self, path: str, message: str) -> None:
        self.path = path
        super().__init__(message)


class DisplayScalingWarning(UserWarning):
    """Samples of unknown transfer (8-bit renderings): design Pfa values do not hold."""


def _tensor(a: np.ndarray, dtype: torch.dtype) -> torch.Tensor:
    """``(H, W)`` -> ``(1, H, W)``; ``(C, H, W)`` kept."""
    t = torch.from_numpy(np.ascontiguousarray(a)).to(dtype)
    return t[None] if t.ndim == 2 else t


def make_item(
    intensity: np.ndarray,
    instances: np.ndarray,
    ignore: np.ndarray,
    meta: dict,
    boxes: list | None = None,
) -> dict:
    """Assemble the item dict (``image, mask, instances, ignore, meta``) from ``(H, W)``
    arrays; ``boxes`` default to the instances' bounding boxes."""
    meta = dict(meta)
    meta["boxes"] = [tuple(b) for b in (boxes if boxes is not None else boxes_of(instances))]
    meta.setdefault("classes", ["target"] * len(meta["boxes"]))
    return {
        "image": _tensor(intensity, torch.float32),
        "mask": _tensor(instances > 0, torch.bool),
        "instances": _tensor(instances, torch.int32),
        "ignore": _tensor(ignore, torch.bool),
        "meta": meta,
    }


class FileDataset(Dataset, ABC):
    """Base of the file-backed datasets.

    Subclasses fill ``self.items`` (one entry per item), implement ``load(i) -> item`` and
    ``item_files(i)`` (the files item ``i`` reads, for the manifest), may list files every
    item shares in ``self.shared_files`` (an annotation file), then call :meth:`finish`.
    A :class:`~torchsar.io.FileFormatError` while loading becomes :class:`BadItemError`.
    """

    scheme = ""

    def __init__(self, root: str | Path, *, sample_type: str, spacing, max_pixels: int) -> None:
        self.root = Path(root)
        self.sample_type = sample_type
        self.spacing = spacing
        self.max_pixels = max_pixels
        self.name = f"{self.scheme}:{root}"
        self.shared_files: list[Path] = []
        self.options: dict = {
            "scheme": self.scheme,
            "root": str(self.root),
            "sample_type": sample_type,
            "pixel_spacing": spacing,
            "max_pixels": max_pixels,
        }

    def finish(self, mode: str, limit: int | None) -> None:
        """After listing: apply ``limit``, warn for display data, check instance counts."""
        self.limit(limit)
        self.options["instances"] = mode
        if self.sample_type == "display":
            warnings.warn(
                f"dataset {self.name} is declared type=display (a rendering of unknown "
                "transfer): detectors' design Pfa is not meaningful on it; declare "
                "?type=amplitude|intensity|db if the samples are calibrated",
                DisplayScalingWarning,
                stacklevel=2,
            )
        check_instance_counts(self.name, self._sample(), mode)

    def _sample(self) -> list[dict]:
        """The first readable items (up to SANITY_ITEMS); bad files are left for the run to
        report (or skip), so building a dataset never fails on one unreadable item."""
        items = []
        for i in range(min(len(self), SANITY_ITEMS)):
            try:
                items.append(self[i])
            except BadItemError:
                continue
        return items

    def limit(self, n: int | None) -> None:
        """Keep the first ``n`` items (subclasses hold their item list in ``self.items``)."""
        if n is not None:
            self.items = self.items[:n]
        self.options["limit"] = n

    def __len__(self) -> int:
        return len(self.items)

    def manifest(self) -> dict:
        """File count, bytes and hash of the files behind this dataset (see file_manifest)."""
        files = {f for i in range(len(self)) for f in self.item_files(i)}
        return file_manifest(self.root, sorted(files | set(self.shared_files)))

    def check_pixels(self, path: Path) -> tuple[int, ...]:
        """The raster's header shape, refused (naming the option that raises the limit)
        when its ``H * W`` is over ``max_pixels``; nothing is decoded."""
        shape = raster_shape(path)
        pixels = shape[0] * shape[1] if len(shape) >= 2 else 0
        if pixels > self.max_pixels:
            raise FileFormatError(
                path,
                f"is {shape[1]}x{shape[0]} = {pixels:,} pixels, over the limit of "
                f"{self.max_pixels:,}; raise it with the dataset option max_pixels=N, e.g. "
                f"{self.scheme}:{self.root}?max_pixels={pixels}",
            )
        return shape

    def intensity(self, samples: np.ndarray, path: Path) -> np.ndarray:
        """The one conversion of this dataset's samples to intensity."""
        try:
            return to_intensity(samples, self.sample_type)
        except TorchSARError as exc:
            raise BadItemError(str(path), f"{path}: {exc} (declared ?type=...)") from exc

    def base_meta(self, name: str, path: Path, cls: str | None, gt: str = "mask") -> dict:
        """The meta keys every item carries."""
        return {
            "name": name,
            "path": str(path),
            "class": cls,
            "gt": gt,
            "pixel_spacing": self.spacing,
            "sample_type": self.sample_type,
        }

    def __getitem__(self, i: int) -> dict:
        return self._checked(self.load, i)

    def truth(self, i: int) -> dict:
        """Item ``i`` for scoring saved predictions: its ground truth, with an image of the
        right shape that need not hold the samples (see :meth:`load_truth`)."""
        return self._checked(self.load_truth, i)

    def _checked(self, load, i: int) -> dict:
        """``load(i)`` for an index in range, a file error as :class:`BadItemError`."""
        if not 0 <= i < len(self):
            raise IndexError(f"item {i} out of range for {len(self)} items")
        try:
            return load(i)
        except FileFormatError as exc:
            raise BadItemError(exc.path, str(exc)) from exc

    def load_truth(self, i: int) -> dict:
        """:meth:`truth` (may raise FileFormatError); default: the whole item."""
        return self.load(i)

    @abstractmethod
    def load(self, i: int) -> dict:
        """Item ``i`` (may raise FileFormatError)."""

    @abstractmethod
    def item_files(self, i: int) -> list[Path]:
        """The files item ``i`` reads."""

    def item_key(self, i: int) -> dict:
        """What identifies item ``i`` without reading it: ``name`` (as in its meta) and
        ``path`` (its image file), and ``image_id`` where the annotations give one."""
        path = self.item_files(i)[0]
        return {"name": str(path.relative_to(self.root)), "path": str(path)}


def require_dir(root: Path, scheme: str) -> None:
    """Refuse a missing dataset folder."""
    if not root.is_dir():
        raise EvalError(f"{scheme} dataset folder {root} does not exist or is not a folder")


def _unlistable(exc: OSError) -> None:
    """os.walk's error hook: a folder that cannot be listed would silently drop its files."""
    raise EvalError(
        f"cannot list folder {exc.filename} ({exc.strerror}); its images would be left out"
    )


def walk_files(root: Path) -> list[Path]:
    """Every file under ``root`` in sorted order, without following directory symlinks
    (file symlinks are kept; the manifest reports those that leave ``root``).

    Raises:
        EvalError: a folder under ``root`` cannot be listed (permissions).
    """
    out = []
    for dirpath, dirnames, filenames in os.walk(root, onerror=_unlistable, followlinks=False):
        dirnames.sort()
        out.extend(Path(dirpath) / f for f in sorted(filenames))
    return sorted(out)
