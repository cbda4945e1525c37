"""``sicd:FILE[?chip=N]``: a SICD / NITF complex product cut into ``N x N`` chips (raster
order, whole chips only; one chip when the image is smaller), read one chip at a time
through the optional sarpy package (``pip install 'sarpy>=1.3'``). No ground truth: use
it to measure clutter statistics and false alarms. Pixel spacing from the SICD grid."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from torchsar.io import read_sicd, sicd_shape
from torchsar_eval.datasets.base import FileDataset, make_item
from torchsar_eval.datasets.spec import DEFAULT_MAX_PIXELS, DatasetSpec
from torchsar_eval.errors import EvalError

__all__ = ["SICD_OPTIONS", "SicdDataset"]

SICD_OPTIONS = ("chip", "spacing", "max_pixels")


def chip_regions(rows: int, cols: int, chip: int) -> list[tuple[int, int, int, int]]:
    """Whole ``chip x chip`` regions in raster order (the whole image if it is smaller)."""
    if rows < chip or cols < chip:
        return [(0, 0, rows, cols)]
    return [
        (r, c, r + chip, c + chip)
        for r in range(0, rows - chip + 1, chip)
        for c in range(0, cols - chip + 1, chip)
    ]


class SicdDataset(FileDataset):
    """Chips of one SICD product (see the module docstring)."""

    scheme = "sicd"

    def __init__(
        self,
        path: str | Path,
        *,
        chip: int = 512,
        limit: int | None = None,
        spacing: tuple[float, float] | None = None,
        max_pixels: int = DEFAULT_MAX_PIXELS,
    ) -> None:
        if not Path(path).is_file():
            raise EvalError(f"sicd product {path} does not exist or is not a file")
        super().__init__(path, sample_type="complex", spacing=spacing, max_pixels=max_pixels)
        try:
            self.items = chip_regions(*sicd_shape(path), chip)
        except ImportError as exc:
            raise EvalError(str(exc)) from exc
        self.options.update(chip=chip, labels="none (clutter only)")
        self.finish("none", limit)

    def item_files(self, i: int) -> list[Path]:
        return [self.root]

    def item_key(self, i: int) -> dict:
        r = self.items[i]
        return {"name": f"{self.root.name}@{r[0]},{r[1]}", "path": str(self.root)}

    def load(self, i: int) -> dict:
        region = self.items[i]
        chip = read_sicd(self.root, region=region, max_pixels=self.max_pixels)
        shape = chip.samples.shape
        meta = self.base_meta(f"{self.root.name}@{region[0]},{region[1]}", self.root, None)
        meta.update(pixel_spacing=self.spacing or chip.pixel_spacing, region=region, classes=[])
        empty = np.zeros(shape, np.int32)
        return make_item(self.intensity(chip.samples, self.root), empty, empty > 0, meta)


def sicd_from_spec(spec: DatasetSpec, limit: int | None) -> SicdDataset:
    """``sicd:FILE?chip=N&spacing=...``."""
    spec.check_keys(SICD_OPTIONS)
    return SicdDataset(
        spec.path,
        chip=spec.positive_int("chip", 512),
        limit=limit,
        spacing=spec.spacing(),
        max_pixels=spec.max_pixels(),
    )
