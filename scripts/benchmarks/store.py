"""Benchmark cases: reading a dataset item by item, from a store against from its files.

``ours`` reads every item of a store written by ``torchsar-eval make-dataset``;
``reference`` reads the same items from the source folder (image decoding, label maps,
instances). The MSTAR SARBake chips of ``../shared/data`` when they are there, else a
folder of simulated chips written as PNG label maps and float TIFF images.
Run: ``python scripts/benchmark.py --topic store``.
"""

from __future__ import annotations

import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import tifffile
from PIL import Image

import torchsar as ts
from torchsar_eval.datasets.make import make_dataset
from torchsar_eval.store import write_store

_DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "mstar_sarbake"


def _simulated_folder(root: Path, n: int) -> str:
    """``n`` simulated chips as ``<stem>.tif`` images beside ``<stem>.mask.png`` labels."""
    b = ts.simulate.chips(n, seed=0)
    for i in range(n):
        tifffile.imwrite(root / f"c{i:04d}.tif", b[i]["image"][0].numpy())
        Image.fromarray(b[i]["mask"][0].numpy().astype(np.uint8)).save(root / f"c{i:04d}.mask.png")
    return f"folder:{root}"


def _read_all(ds) -> None:
    for i in range(len(ds)):
        ds[i]


def cases() -> list[tuple[str, Callable[[], object], Callable[[], object]]]:
    tmp = Path(tempfile.mkdtemp(prefix="torchsar-store-bench-"))
    if _DATA.is_dir():
        spec, what = f"folder:{_DATA}?variant=linear", "MSTAR SARBake (linear JPEG)"
    else:
        (tmp / "folder").mkdir()
        spec, what = _simulated_folder(tmp / "folder", 100), "100 simulated chips (TIFF + PNG)"
    warnings.simplefilter("ignore")  # display-scaled JPEGs say so once per item
    folder = make_dataset(spec)
    write_store((folder[i] for i in range(len(folder))), len(folder), tmp / "store")
    store = make_dataset(f"store:{tmp / 'store'}")
    return [
        (
            f"read every item, {what} x{len(folder)}: store / folder",
            lambda: _read_all(store),
            lambda: _read_all(folder),
        )
    ]
