"""Stored datasets: WebDataset-style tar shards with a random-access index.

``torchsar-eval make-dataset`` writes any dataset (simulated or read from files) into a
folder::

    store.json           format, version, item count, shard size, source and its options
    index.npy            int64 (N, 5, 2): byte offset and size of each item's 5 members
    shard-000000.tar ... members <key>.image.npy, .mask.npy, .instances.npy, .ignore.npy, .json

Tar shards are the WebDataset layout (one sample = files sharing a key), so
``ray.data.read_webdataset`` and the ``webdataset`` package read them as they are, and a
shard is one sequential file for object stores. The index gives random access by item: a
read opens the shard, reads the item's five consecutive members at once and closes it, so
no file handle is ever held across a fork. Item ``i`` of the store is item ``i`` of its source.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import tarfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from torchsar_eval.errors import EvalError
from torchsar_eval.npy import read_npy

__all__ = ["FIELDS", "StoreDataset", "write_store"]

FIELDS = ("image", "mask", "instances", "ignore")
FORMAT = "torchsar-store"
VERSION = 1


def _jsonable(value: object) -> object:
    """``value`` with tuples as lists and numpy scalars as Python numbers; arrays, tensors and
    other objects are dropped (``None`` marks them)."""
    if isinstance(value, dict):
        out = {str(k): _jsonable(v) for k, v in value.items()}
        return {k: v for k, v in out.items() if v is not _DROP}
    if isinstance(value, list | tuple):
        return [v for v in (_jsonable(v) for v in value) if v is not _DROP]
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return _DROP


_DROP = object()


def _add(tar: tarfile.TarFile, name: str, data: bytes) -> tuple[int, int]:
    info = tarfile.TarInfo(name)
    info.size = len(data)
    tar.addfile(info, io.BytesIO(data))
    return tar.offset - tarfile.BLOCKSIZE * (-(-len(data) // tarfile.BLOCKSIZE)), len(data)


def _npy(t: torch.Tensor) -> bytes:
    buf = io.BytesIO()
    np.save(buf, t.cpu().numpy(), allow_pickle=False)
    return buf.getvalue()


def _write_item(tar: tarfile.TarFile, key: str, item: dict) -> np.ndarray:
    """Add one sample's members; return their ``(offset, size)`` rows."""
    rows = [_add(tar, f"{key}.{f}.npy", _npy(item[f])) for f in FIELDS]
    rows.append(_add(tar, f"{key}.json", json.dumps(_jsonable(item["meta"])).encode()))
    return np.array(rows, dtype=np.int64)


def write_store(
    items: Iterable[dict], n: int, out: Path, *, shard_size: int = 1000, info: dict | None = None
) -> Path:
    """Write ``n`` items into a new store folder ``out`` (built beside it, then renamed)."""
    out = Path(out)
    if out.exists():
        raise EvalError(f"--out {out} already exists; choose a new folder")
    tmp = out.with_name(f".{out.name}.partial-{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    index = np.zeros((n, len(FIELDS) + 1, 2), dtype=np.int64)
    try:
        it = iter(items)
        for k, start in enumerate(range(0, n, shard_size)):
            with tarfile.open(tmp / f"shard-{k:06d}.tar", "w", format=tarfile.USTAR_FORMAT) as tar:
                for i in range(start, min(start + shard_size, n)):
                    index[i] = _write_item(tar, f"{i:09d}", next(it))
        np.save(tmp / "index.npy", index)
        header = {"format": FORMAT, "version": VERSION, "n": n, "shard_size": shard_size,
                  "fields": [*FIELDS, "json"], **(info or {})}  # fmt: skip
        (tmp / "store.json").write_text(json.dumps(header, indent=2, default=str) + "\n")
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


class StoreDataset(Dataset):
    """A store written by :func:`write_store`, read lazily item by item (``store:PATH``)."""

    def __init__(self, root: str | Path, *, limit: int | None = None) -> None:
        self.root = Path(root)
        head = self.root / "store.json"
        if not head.is_file():
            raise EvalError(f"{self.root} is not a torchsar store (no store.json)")
        self.header = json.loads(head.read_text())
        if self.header.get("format") != FORMAT or self.header.get("version") != VERSION:
            raise EvalError(f"{head}: not a {FORMAT} version {VERSION} header")
        self.n = int(self.header["n"]) if limit is None else min(limit, int(self.header["n"]))
        self._index: np.ndarray | None = None  # loaded on first access (after any fork)
        self.name = f"store:{root}"
        self.options = {"root": str(self.root), "limit": limit, "source": self.header}

    def __len__(self) -> int:
        return self.n

    def _read(self, shard: Path, rows: np.ndarray) -> list[memoryview]:
        """An item's members: one read from its first member to the end of its last (they
        are consecutive in the tar), cut at the index's offsets."""
        first, end = int(rows[0, 0]), int(rows[-1, 0] + rows[-1, 1])
        with open(shard, "rb") as f:
            f.seek(first)
            data = f.read(end - first)
        if len(data) != end - first:
            raise EvalError(f"store {self.root} is truncated (member at byte {first})")
        view = memoryview(data)
        return [view[int(o) - first : int(o + s) - first] for o, s in rows]

    def __getitem__(self, i: int) -> dict:
        if not 0 <= i < self.n:
            raise IndexError(i)
        if self._index is None:
            self._index = np.load(self.root / "index.npy", mmap_mode="r")
        shard = self.root / f"shard-{i // int(self.header['shard_size']):06d}.tar"
        parts = self._read(shard, np.asarray(self._index[i]))
        out = {k: torch.from_numpy(read_npy(b)) for k, b in zip(FIELDS, parts, strict=False)}
        out["meta"] = json.loads(bytes(parts[-1]))
        return out

    def manifest(self) -> dict:
        """Files, bytes and the store header (the store is the data's identity)."""
        files = sorted(p for p in self.root.iterdir() if p.is_file())
        return {"files": len(files), "bytes": sum(p.stat().st_size for p in files),
                "header": self.header}  # fmt: skip

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["_index"] = None  # never ship the memory map to a worker
        return state
