"""``phoenix:DIR``: MSTAR raw Phoenix files (magnitude + phase), found by their header tag.

Samples: the magnitude plane, declared ``amplitude`` (``?type=complex`` uses magnitude and
phase; the intensity is the same). Pixel spacing: the header's range x cross-range pixel
spacing unless ``?spacing=`` overrides it. Ground truth: a ``<file>.mask.png`` label map
beside the file when present (same labels and options as ``folder:``), else none. The
image-level class is the parent folder's name below ``DIR``, else the header's TargetType.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from torchsar.io import RASTER_EXTS, FileFormatError, is_phoenix, read_phoenix
from torchsar_eval.datasets.base import FileDataset, make_item, require_dir, walk_files
from torchsar_eval.datasets.images import read_labels
from torchsar_eval.datasets.semantics import (
    INSTANCE_MODES,
    SHADOW_MODES,
    form_instances,
    split_labels,
)
from torchsar_eval.datasets.spec import DEFAULT_MAX_PIXELS, DatasetSpec
from torchsar_eval.errors import EvalError

__all__ = ["PHOENIX_OPTIONS", "PhoenixDataset"]

PHOENIX_OPTIONS = ("type", "spacing", "shadow", "instances", "max_pixels")


class PhoenixDataset(FileDataset):
    """MSTAR Phoenix chips (see the module docstring)."""

    scheme = "phoenix"

    def __init__(
        self,
        root: str | Path,
        *,
        limit: int | None = None,
        sample_type: str = "amplitude",
        spacing: tuple[float, float] | None = None,
        shadow: str = "ignore",
        instances: str = "one-per-image",
        max_pixels: int = DEFAULT_MAX_PIXELS,
    ) -> None:
        require_dir(Path(root), self.scheme)
        if sample_type not in ("amplitude", "complex"):
            raise EvalError(f"phoenix data are amplitude or complex, not type={sample_type}")
        super().__init__(root, sample_type=sample_type, spacing=spacing, max_pixels=max_pixels)
        skip = (*RASTER_EXTS, ".txt", ".xml", ".json")
        self.items = [
            f
            for f in walk_files(self.root)
            if f.suffix.lower() not in skip and f.is_file() and is_phoenix(f)
        ]
        if not self.items:
            raise EvalError(f"no MSTAR Phoenix files found in {self.root}")
        self.shadow = shadow
        self.options.update(shadow=shadow, spacing_source="option" if spacing else "header")
        self.finish(instances, limit)

    @staticmethod
    def _mask(path: Path) -> Path:
        return path.with_name(path.name + ".mask.png")

    def _ground_truth(self, path: Path, shape: tuple[int, int]):
        """``(target, ignore)`` from the mask beside the file, or empty."""
        mask = self._mask(path)
        if not mask.exists():
            return np.zeros(shape, bool), np.zeros(shape, bool)
        lab = read_labels(mask, max_pixels=self.max_pixels)
        if lab.shape != shape:
            raise FileFormatError(mask, f"is {lab.shape[1]}x{lab.shape[0]}, chip is {shape}")
        return split_labels(lab, self.shadow)

    def item_files(self, i: int) -> list[Path]:
        mask = self._mask(self.items[i])
        return [self.items[i], mask] if mask.exists() else [self.items[i]]

    def load(self, i: int) -> dict:
        path = self.items[i]
        chip = read_phoenix(path, max_pixels=self.max_pixels)
        samples = chip.complex if self.sample_type == "complex" else chip.magnitude
        target, ignore = self._ground_truth(path, chip.magnitude.shape)
        inst = form_instances(target, self.options["instances"])
        cls = path.parent.name if path.parent != self.root else chip.header.get("TargetType")
        meta = self.base_meta(str(path.relative_to(self.root)), path, cls)
        meta["pixel_spacing"] = self.spacing or chip.pixel_spacing
        meta["classes"] = [cls or "target"] * int(inst.max(initial=0))
        meta["shadow"] = self.shadow  # "ignore": the ignore pixels are radar shadow
        return make_item(self.intensity(samples, path), inst, ignore, meta)


def phoenix_from_spec(spec: DatasetSpec, limit: int | None) -> PhoenixDataset:
    """``phoenix:DIR?options``."""
    spec.check_keys(PHOENIX_OPTIONS)
    return PhoenixDataset(
        spec.path,
        limit=limit,
        sample_type=spec.sample_type("amplitude"),
        spacing=spec.spacing(),
        shadow=spec.choice("shadow", SHADOW_MODES, "ignore"),
        instances=spec.choice("instances", INSTANCE_MODES[:2], "one-per-image"),
        max_pixels=spec.max_pixels(),
    )
