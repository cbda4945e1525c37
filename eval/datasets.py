"""Datasets of the harness: simulated chips and scenes, and folders of image/mask pairs.

Every dataset yields dicts with ``image`` ``(C, H, W)`` float32 intensity, ``mask``
``(C, H, W)`` bool target pixels, ``instances`` ``(C, H, W)`` int32 ids, ``ignore``
``(C, H, W)`` bool don't-care pixels and ``meta`` (a dict with at least ``name``).

Names accepted by :func:`make_dataset`:

- ``sim-chips``: MSTAR-like 128x128 chips, one vehicle each (``torchsar.simulate.chips``).
- ``sim-scenes``: 512x512 scenes with clutter edges, groups and large structures.
- ``folder:PATH``: ``<stem>.mask.png`` label maps (0 clutter, 1 target, 2 ignore) beside
  ``<stem>.png|jpg|jpeg`` images (8-bit magnitude; squared to intensity). Alternate
  renderings ``<stem>.<variant>.<ext>`` (e.g. MSTAR's ``.linear.jpeg``) are chosen with
  ``folder:PATH?variant=linear``. Instances are the 8-connected components of the target
  label unless an ``<stem>.instances.png`` id map is present.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

import torchsar as ts
from eval.errors import EvalError
from torchsar.metrics import label_components

__all__ = ["DATASETS", "FolderDataset", "SimDataset", "make_dataset", "read_image"]

IMAGE_EXTS = (".png", ".jpg", ".jpeg")
DATASETS = ("sim-chips", "sim-scenes", "folder:PATH")
DEFAULT_N = {"sim-chips": 96, "sim-scenes": 6}


class SimDataset(Dataset):
    """Simulated chips or scenes, generated once (seeded) and served from memory."""

    def __init__(self, kind: str, n: int, seed: int, **options: object) -> None:
        make = ts.simulate.chips if kind == "sim-chips" else ts.simulate.scenes
        self.name = kind
        self.batch = make(n, seed=seed, **options)
        self.options = {"n": n, "seed": seed, **options}

    def __len__(self) -> int:
        return len(self.batch)

    def __getitem__(self, i: int) -> dict:
        item = self.batch[i]
        item["meta"] = {"name": f"{self.name}/{i}", **item["meta"]}
        return item


def read_image(path: Path) -> np.ndarray:
    """Read an 8-bit (or 16-bit) image as a 2-D float array; colour is averaged to grey."""
    from skimage import io

    try:
        a = io.imread(path)
    except Exception as exc:  # unreadable or corrupt file: name it
        raise EvalError(f"cannot read image {path}: {exc}") from exc
    if a.ndim == 3:
        a = a[..., :3].mean(axis=-1)
    return np.asarray(a, dtype=np.float64)


class FolderDataset(Dataset):
    """Image / mask pairs from a folder (recursively), the format of MSTAR SARBake chips."""

    def __init__(self, root: str | Path, *, variant: str | None = None, limit: int | None = None):
        self.root = Path(root)
        self.name = f"folder:{root}"
        self.variant = variant
        if not self.root.is_dir():
            raise EvalError(f"dataset folder {self.root} does not exist or is not a folder")
        self.items = self._pair_files()
        if limit is not None:
            self.items = self.items[:limit]
        self.options = {"root": str(self.root), "variant": variant, "limit": limit}

    def _pair_files(self) -> list[tuple[Path, Path]]:
        masks = sorted(self.root.rglob("*.mask.png"))
        stems = {m.with_name(m.name[: -len(".mask.png")]) for m in masks}
        images = [
            p
            for p in sorted(self.root.rglob("*"))
            if p.suffix.lower() in IMAGE_EXTS
            and not p.name.endswith((".mask.png", ".instances.png"))
        ]
        pairs, orphans = [], []
        for img in images:
            base = img.with_suffix("")
            if base in stems and self.variant is None:
                pairs.append((img, base.with_name(base.name + ".mask.png")))
            elif base.suffix and base.with_suffix("") in stems:
                if base.suffix[1:] == self.variant:
                    stem = base.with_suffix("")
                    pairs.append((img, stem.with_name(stem.name + ".mask.png")))
            elif base not in stems:
                orphans.append(img)
        if orphans:
            raise EvalError(
                f"image {orphans[0]} has no mask {orphans[0].with_suffix('')}.mask.png "
                f"({len(orphans)} image(s) without a mask in {self.root})"
            )
        if not pairs:
            what = f" of variant {self.variant!r}" if self.variant else ""
            raise EvalError(f"no images{what} with <stem>.mask.png masks found in {self.root}")
        return pairs

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, i: int) -> dict:
        img_path, mask_path = self.items[i]
        img = read_image(img_path)
        lab = read_image(mask_path).astype(np.int64)
        if lab.shape != img.shape:
            raise EvalError(
                f"mask {mask_path} is {lab.shape[1]}x{lab.shape[0]} but image {img_path} is "
                f"{img.shape[1]}x{img.shape[0]}"
            )
        bad = np.setdiff1d(np.unique(lab), [0, 1, 2])
        if bad.size:
            raise EvalError(f"mask {mask_path} has labels {bad.tolist()}; expected 0, 1, 2")
        scale = 255.0 if img.max() <= 255 else 65535.0
        intensity = (img / scale) ** 2
        inst_path = mask_path.with_name(mask_path.name.replace(".mask.png", ".instances.png"))
        if inst_path.exists():
            inst = read_image(inst_path).astype(np.int64) * (lab == 1)
        else:
            inst, _ = label_components(lab == 1, connectivity=2)
        as_t = lambda a, dt: torch.from_numpy(np.ascontiguousarray(a)).to(dt)[None]  # noqa: E731
        return {
            "image": as_t(intensity, torch.float32),
            "mask": as_t(lab == 1, torch.bool),
            "instances": as_t(inst, torch.int32),
            "ignore": as_t(lab == 2, torch.bool),
            "meta": {"name": str(img_path.relative_to(self.root)), "path": str(img_path)},
        }


def _parse_folder(spec: str) -> tuple[str, dict[str, str]]:
    path, _, query = spec[len("folder:") :].partition("?")
    opts = dict(kv.split("=", 1) for kv in query.split("&") if "=" in kv)
    unknown = set(opts) - {"variant"}
    if unknown:
        raise EvalError(f"unknown folder option(s) {sorted(unknown)}; allowed: variant")
    return path, opts


def make_dataset(spec: str, *, n: int | None = None, seed: int = 0) -> Dataset:
    """Build a dataset from its name (see the module docstring); ``n`` limits its size."""
    if spec in ("sim-chips", "sim-scenes"):
        return SimDataset(spec, DEFAULT_N[spec] if n is None else n, seed)
    if spec.startswith("folder:"):
        path, opts = _parse_folder(spec)
        return FolderDataset(path, variant=opts.get("variant"), limit=n)
    raise EvalError(f"unknown dataset {spec!r}; valid: {', '.join(DATASETS)}")
