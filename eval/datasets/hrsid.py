"""``hrsid:DIR``: HRSID chips ``<name>.png`` with ``<name>_instance_id_RGB.png`` id maps.

Each colour of the id map is one ship (black = sea), decoded colour -> id; touching ships
keep their own colours, so counting connected components of the ship mask would merge them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from torchsar.io import decode_id_map, read_raster
from torchsar_eval.datasets.base import FileDataset, make_item, require_dir, walk_files
from torchsar_eval.datasets.images import check_same_size, read_samples
from torchsar_eval.datasets.spec import DEFAULT_MAX_PIXELS, DatasetSpec
from torchsar_eval.errors import EvalError

__all__ = ["HRSID_OPTIONS", "HrsidDataset"]

HRSID_OPTIONS = ("type", "spacing", "max_pixels")
ID_SUFFIX = "_instance_id_RGB.png"


class HrsidDataset(FileDataset):
    """HRSID chips and their instance-colour maps (class ``ship``)."""

    scheme = "hrsid"

    def __init__(
        self,
        root: str | Path,
        *,
        limit: int | None = None,
        sample_type: str = "display",
        spacing: tuple[float, float] | None = None,
        max_pixels: int = DEFAULT_MAX_PIXELS,
    ) -> None:
        require_dir(Path(root), self.scheme)
        super().__init__(root, sample_type=sample_type, spacing=spacing, max_pixels=max_pixels)
        id_maps = [f for f in walk_files(self.root) if f.name.endswith(ID_SUFFIX)]
        self.items = [(m.with_name(m.name[: -len(ID_SUFFIX)] + ".png"), m) for m in id_maps]
        missing = [str(img) for img, _ in self.items if not img.exists()]
        if missing:
            raise EvalError(f"id map(s) without image: {missing[0]} missing ({len(missing)})")
        if not self.items:
            raise EvalError(f"no <name>{ID_SUFFIX} id maps found in {self.root}")
        self.options["labels"] = "one colour per ship (black = sea)"
        self.finish("idmap", limit)

    def item_files(self, i: int) -> list[Path]:
        return list(self.items[i])

    def load(self, i: int) -> dict:
        img_path, ids_path = self.items[i]
        check_same_size(img_path, ids_path)
        samples = read_samples(img_path, self.sample_type, max_pixels=self.max_pixels)
        inst = decode_id_map(read_raster(ids_path, max_pixels=self.max_pixels), str(ids_path))
        meta = self.base_meta(str(img_path.relative_to(self.root)), img_path, None)
        meta["classes"] = ["ship"] * int(inst.max(initial=0))
        meta["id_map"] = str(ids_path)
        return make_item(self.intensity(samples, img_path), inst, np.zeros(inst.shape, bool), meta)


def hrsid_from_spec(spec: DatasetSpec, limit: int | None) -> HrsidDataset:
    """Build an :class:`HrsidDataset` from ``hrsid:DIR?options``."""
    spec.check_keys(HRSID_OPTIONS)
    return HrsidDataset(
        spec.path,
        limit=limit,
        sample_type=spec.sample_type("display"),
        spacing=spec.spacing(),
        max_pixels=spec.max_pixels(),
    )
