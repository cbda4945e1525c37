"""``folder:PATH``: image files beside ``<stem>.mask.png`` label maps (MSTAR SARBake layout).

Pairing: every ``<stem>.mask.png`` needs exactly one image ``<stem>.<ext>`` (or
``<stem>.<variant>.<ext>`` with ``?variant=``), ``ext`` one of png, jpg, jpeg, tif, tiff.
A mask without an image, an image without a mask, two images sharing one mask, and one
image file reached twice (through a symlink, a hard link or a ``..`` path: it would be
scored twice) are errors naming the files; FIFOs and devices are refused without being
opened, sidecar text files over a few kilobytes without being read.
Pixel spacing: ``?spacing=ROW[,COL]``, else a ``<stem>.spacing.txt`` sidecar holding
``ROW [COL]`` in metres, else a projected GeoTIFF's pixel scale, else unknown (``None``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from torchsar.io import (
    RASTER_EXTS,
    TIFF_EXTS,
    FileFormatError,
    decode_id_map,
    geotiff_pixel_spacing,
    read_raster,
    tiff_dtype,
)
from torchsar_eval.datasets.base import FileDataset, make_item, require_dir, walk_files
from torchsar_eval.datasets.files import read_small, require_regular, same_files
from torchsar_eval.datasets.images import check_same_size, read_labels, read_samples
from torchsar_eval.datasets.semantics import (
    INSTANCE_MODES,
    SHADOW_MODES,
    form_instances,
    split_labels,
)
from torchsar_eval.datasets.spec import DEFAULT_MAX_PIXELS, DatasetSpec, parse_spacing
from torchsar_eval.errors import EvalError

__all__ = ["FOLDER_OPTIONS", "FolderDataset"]

FOLDER_OPTIONS = ("variant", "type", "spacing", "shadow", "instances", "max_pixels")
MASK, IDS, BOX, SPACING = ".mask.png", ".instances.png", ".box.txt", ".spacing.txt"
SIDECAR_LIMIT = 256  # bytes of a spacing sidecar ("ROW [COL]" metres)


def _stem_and_variant(img: Path, stems: set[Path]) -> tuple[Path, str | None] | None:
    """The mask stem an image belongs to and its variant, or ``None`` for an orphan."""
    base = img.with_suffix("")
    if base in stems:
        return base, None
    if base.suffix and base.with_suffix("") in stems:
        return base.with_suffix(""), base.suffix[1:]
    return None


def pair_files(root: Path, variant: str | None) -> list[tuple[Path, Path]]:
    """``(image, mask)`` pairs in sorted order; every rule of the module docstring checked."""
    files = walk_files(root)
    masks = [f for f in files if f.name.endswith(MASK)]
    stems = {m.with_name(m.name[: -len(MASK)]) for m in masks}
    chosen: dict[Path, list[Path]] = {s: [] for s in stems}
    for f in files:
        if f.suffix.lower() not in RASTER_EXTS or f.name.endswith((MASK, IDS)):
            continue
        require_regular(f, "image")
        found = _stem_and_variant(f, stems)
        if found is None:
            raise EvalError(f"image {f} has no mask {f.with_suffix('')}{MASK}")
        if found[1] == variant:
            chosen[found[0]].append(f)
    pairs = []
    for stem in sorted(chosen):
        mask = stem.with_name(stem.name + MASK)
        imgs = chosen[stem]
        if len(imgs) > 1:
            raise EvalError(
                f"mask {mask} is shared by {len(imgs)} images: {', '.join(map(str, imgs))}"
            )
        if not imgs:
            what = f" of variant {variant!r}" if variant else ""
            raise EvalError(f"mask {mask} has no image{what} ({stem.name}.<png|jpeg|tif>)")
        pairs.append((imgs[0], mask))
    if not pairs:
        raise EvalError(f"no images with <stem>{MASK} masks found in {root}")
    for first, again in same_files(img for img, _ in pairs):
        raise EvalError(
            f"image {again} is the same file as {first} (a symlink, hard link or '..' path "
            "to it): it would be scored twice; keep one of them"
        )
    return pairs


def _default_type(image: Path, variant: str | None) -> str:
    """complex / float TIFF -> complex / intensity; 8/16-bit -> display (``linear`` variant:
    amplitude, as MSTAR SARBake's linear magnitude renderings)."""
    if image.suffix.lower() in (".tif", ".tiff"):
        kind = tiff_dtype(image).kind
        if kind in "cf":
            return "complex" if kind == "c" else "intensity"
    return "amplitude" if variant == "linear" else "display"


def _default_instances(pairs: list[tuple[Path, Path]]) -> str:
    """``idmap`` when id maps exist; ``one-per-image`` when every mask has a ``.box.txt``
    (one target box per chip, the MSTAR SARBake layout); else ``components``."""
    stems = [m.with_name(m.name[: -len(MASK)]) for _, m in pairs]
    if any(s.with_name(s.name + IDS).exists() for s in stems):
        return "idmap"
    if all(s.with_name(s.name + BOX).exists() for s in stems):
        return "one-per-image"
    return "components"


class FolderDataset(FileDataset):
    """Image / mask pairs from a folder (recursively); see the module docstring."""

    scheme = "folder"

    def __init__(
        self,
        root: str | Path,
        *,
        variant: str | None = None,
        limit: int | None = None,
        sample_type: str | None = None,
        spacing: tuple[float, float] | None = None,
        shadow: str = "ignore",
        instances: str | None = None,
        max_pixels: int = DEFAULT_MAX_PIXELS,
    ) -> None:
        require_dir(Path(root), self.scheme)
        self.items = pair_files(Path(root), variant)
        sample_type = sample_type or _default_type(self.items[0][0], variant)
        super().__init__(root, sample_type=sample_type, spacing=spacing, max_pixels=max_pixels)
        self.variant, self.shadow = variant, shadow
        self.mode = instances or _default_instances(self.items)
        self.options.update(variant=variant, shadow=shadow, labels="0 clutter, 1 target, 2 shadow")
        self.options["spacing_source"] = (
            "option" if spacing else f"<stem>{SPACING}, else GeoTIFF pixel scale, when present"
        )
        self.finish(self.mode, limit)

    def item_files(self, i: int) -> list[Path]:
        """Image, mask, and the id map / spacing sidecar when present."""
        img, mask = self.items[i]
        sidecars = [self._beside(mask, IDS), self._beside(mask, SPACING)]
        return [img, mask, *(p for p in sidecars if p.exists())]

    @staticmethod
    def _beside(mask: Path, suffix: str) -> Path:
        """``<stem><suffix>`` next to ``<stem>.mask.png``."""
        return mask.with_name(mask.name[: -len(MASK)] + suffix)

    def _spacing(self, img: Path, mask: Path) -> tuple[float, float] | None:
        """``?spacing=``, else a ``<stem>.spacing.txt`` sidecar (``ROW [COL]`` metres), else
        a projected GeoTIFF's pixel scale."""
        sidecar = self._beside(mask, SPACING)
        if self.spacing is not None:
            return self.spacing
        if not sidecar.exists():
            tiff = img.suffix.lower() in TIFF_EXTS
            return geotiff_pixel_spacing(img) if tiff else None
        data = read_small(sidecar, SIDECAR_LIMIT, "spacing sidecar")
        text = ",".join(data.decode("utf-8", errors="replace").replace(",", " ").split())
        try:
            return parse_spacing(text)
        except EvalError as exc:
            raise FileFormatError(sidecar, str(exc)) from exc

    def _id_map(self, img: Path, mask: Path, target: np.ndarray) -> np.ndarray:
        """The decoded ``<stem>.instances.png``; every target pixel must have an id."""
        path = self._beside(mask, IDS)
        if not (path.exists() or path.is_symlink()):
            raise FileFormatError(
                path,
                "is missing: instances=idmap (the default when any "
                "mask has one) needs an id map beside every mask; or "
                "pass ?instances=components",
            )
        check_same_size(img, path)
        ids = decode_id_map(read_raster(path, max_pixels=self.max_pixels), str(path))
        missing = int((target & (ids == 0)).sum())
        if missing:
            raise FileFormatError(path, f"gives no instance id to {missing} target pixels")
        return ids

    def _class(self, img: Path) -> str | None:
        """The image-level class: the parent folder's name below the root (MSTAR layout)."""
        return img.parent.name if img.parent != self.root else None

    def load(self, i: int) -> dict:
        img_path, mask_path = self.items[i]
        self.check_pixels(img_path)
        check_same_size(img_path, mask_path)
        samples = read_samples(img_path, self.sample_type, max_pixels=self.max_pixels)
        target, ignore = split_labels(
            read_labels(mask_path, max_pixels=self.max_pixels), self.shadow
        )
        idmap = self._id_map(img_path, mask_path, target) if self.mode == "idmap" else None
        inst = form_instances(target, self.mode, idmap)
        cls = self._class(img_path)
        meta = self.base_meta(str(img_path.relative_to(self.root)), img_path, cls)
        meta["classes"] = [cls or "target"] * int(inst.max(initial=0))
        meta["pixel_spacing"] = self._spacing(img_path, mask_path)
        meta["shadow"] = self.shadow  # "ignore": the ignore pixels are radar shadow
        return make_item(self.intensity(samples, img_path), inst, ignore, meta)


def folder_from_spec(spec: DatasetSpec, limit: int | None) -> FolderDataset:
    """Build a :class:`FolderDataset` from ``folder:PATH?options``."""
    spec.check_keys(FOLDER_OPTIONS)
    return FolderDataset(
        spec.path,
        variant=spec.options.get("variant"),
        limit=limit,
        sample_type=spec.sample_type(None),  # None: decided from the first image
        spacing=spec.spacing(),
        shadow=spec.choice("shadow", SHADOW_MODES, "ignore"),
        instances=spec.choice("instances", INSTANCE_MODES, None),
        max_pixels=spec.max_pixels(),
    )
