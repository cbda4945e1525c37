"""Stored datasets: WebDataset-style tar shards with a random-access index.

``torchsar-eval make-dataset`` writes any dataset (simulated or read from files) into a
folder::

    store.json           format, version, item count, shard size, source and its options
    index.npy            int64 (N, 6, 2): per item, byte offset and size of its 5 members,
                         then (CRC-32 of the item's bytes, 0)
    shard-000000.tar ... members <key>.image.npy, .mask.npy, .instances.npy, .ignore.npy, .json

Tar shards are the WebDataset layout (one sample = files sharing a key), so
``ray.data.read_webdataset`` and the ``webdataset`` package read them as they are, and a
shard is one sequential file for object stores. The index gives random access by item: a
read opens the shard, reads the item's five consecutive members at once and closes it, so
no file handle is ever held across a fork. Item ``i`` of the store is item ``i`` of its source.

What is checked, so that a damaged store is one error naming its file, never a traceback,
a hang or a silently different item:

- on opening: ``store.json`` (a JSON object; ``n`` and ``shard_size`` whole numbers;
  ``n`` equal to the index's length), ``index.npy`` (dtype and shape) and every row of it
  against its shard (members inside the file and in tar order, no two items sharing
  bytes); FIFOs and devices are refused without being opened;
- on reading an item: each member's tar header (the item's own key and the index's size),
  the CRC-32 of the item's bytes, the ``.npy`` headers and the item contract of
  :mod:`torchsar_eval.datasets`: dtypes, equal shapes, a finite non-negative image, and a
  mask that marks exactly the pixels of the instances. A target pixel that no instance
  covers would be lost by object scoring, so such an item is refused (as
  :class:`~torchsar_eval.datasets.BadItemError`, which ``skip_bad`` runs skip), and
  :func:`write_store` refuses to write it in the first place.

Stores of version 1 (no CRC-32) are read with every check but the checksum.

:func:`write_store` builds the store in a hidden ``.<name>.store-partial`` folder beside
``out`` while holding the lock file ``.<name>.store-lock`` (:mod:`torchsar_eval.locks`),
then renames it to ``out``. A second writer of the same ``out`` is refused while the
lock is held. A writer killed outright leaves both behind, with the lock free: the next
:func:`write_store` in that folder removes them (a partial store whose lock is free has no
live writer); by hand, delete ``.<name>.store-partial`` when no make-dataset runs.
"""

from __future__ import annotations

import io
import json
import math
import numbers
import os
import shutil
import tarfile
import zlib
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from torchsar_eval.datasets.base import BadItemError
from torchsar_eval.datasets.files import read_small, require_regular
from torchsar_eval.errors import EvalError
from torchsar_eval.locks import LockHeldError, hold
from torchsar_eval.npy import NpyError, read_npy

__all__ = [
    "FIELDS",
    "StoreDataset",
    "check_item",
    "lock_path",
    "partial_path",
    "remove_dead_partials",
    "write_store",
]

FIELDS = ("image", "mask", "instances", "ignore")
MEMBERS = (*FIELDS, "json")
DTYPES = {"image": np.float32, "mask": np.bool_, "instances": np.int32, "ignore": np.bool_}
FORMAT = "torchsar-store"
VERSION = 2
ROWS = {1: len(MEMBERS), 2: len(MEMBERS) + 1}  # index rows per item, by version
HEADER_LIMIT = 16 << 20  # store.json holds counts and the source's options: kilobytes
LOCK_WAIT_S = 5.0  # how long a writer waits for another writer of the same out
_BLOCK = tarfile.BLOCKSIZE
_PARTIAL, _LOCK = ".store-partial", ".store-lock"


def _member_name(key: str, k: int) -> str:
    return f"{key}.{MEMBERS[k]}" + ("" if MEMBERS[k] == "json" else ".npy")


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


# --- the item contract ------------------------------------------------------------------


def _number(v: object) -> bool:
    return type(v) in (int, float) and math.isfinite(v)


def _check_meta(meta: object, k: int) -> str | None:
    """What is wrong with an item's meta (``k`` instances), or ``None``."""
    if not isinstance(meta, dict):
        return f"meta is a {type(meta).__name__}, not a JSON object"
    boxes, classes = meta.get("boxes"), meta.get("classes")
    if boxes is not None:
        if not isinstance(boxes, list) or len(boxes) < k:
            return f"meta boxes must be a list of a box per instance id 1..{k}, got {_short(boxes)}"
        for b in boxes:
            if not isinstance(b, list) or len(b) != 4 or not all(map(_number, b)):
                return f"meta box {_short(b)} is not 4 numbers (r0, c0, r1, c1)"
    if classes is not None and (not isinstance(classes, list) or len(classes) < k):
        return (
            f"meta classes must be a list of a class per instance id 1..{k}, got {_short(classes)}"
        )
    sp = meta.get("pixel_spacing")
    if sp is not None and not (
        isinstance(sp, list) and len(sp) == 2 and all(_number(v) and v > 0 for v in sp)
    ):
        return f"meta pixel_spacing {_short(sp)} is not two positive numbers (metres)"
    if meta.get("gt", "mask") not in ("mask", "box"):
        return f"meta gt {_short(meta['gt'])} is neither 'mask' nor 'box'"
    pm = meta.get("pixel_m")
    if pm is not None and not (_number(pm) and pm > 0):
        return f"meta pixel_m {_short(pm)} is not a positive number (metres)"
    return None


def check_item(arrays: dict[str, np.ndarray], meta: object) -> str | None:
    """What breaks the item contract (see :mod:`torchsar_eval.datasets`), or ``None``:
    dtypes, equal ``(C, H, W)`` shapes, bools of 0 and 1, a finite non-negative image,
    ids >= 0, a mask that marks exactly the instances' pixels, and a meta with a box and a
    class for every id up to the largest (annotations whose objects got no pixels may
    add more)."""
    for f in FIELDS:
        if f not in arrays:
            return f"has no {f}"
        if arrays[f].dtype != DTYPES[f]:
            return f"{f} has dtype {arrays[f].dtype}, expected {np.dtype(DTYPES[f])}"
    image, mask, inst = (arrays[f] for f in FIELDS[:3])
    if image.ndim != 3 or 0 in image.shape:
        return f"image has shape {image.shape}, expected (C, H, W) of sizes >= 1"
    for f in FIELDS[1:]:
        if arrays[f].shape != image.shape:
            return f"{f} has shape {arrays[f].shape} but image {image.shape}"
    for f in ("mask", "ignore"):
        if arrays[f].view(np.uint8).max() > 1:
            return f"{f} holds bytes other than 0 and 1"
    if not ((image >= 0).all() and image.max() < np.inf):  # NaN fails the first test
        return "image holds NaN, Inf or negative intensity"
    if inst.min() < 0:
        return "instances holds negative ids"
    covered = inst > 0
    if not np.array_equal(mask, covered):
        lost = int(np.count_nonzero(mask & ~covered))
        if lost:
            return (
                f"mask marks {lost} target pixels that no instance covers (object "
                "scoring would miss their targets; give them instance ids)"
            )
        extra = int(np.count_nonzero(covered & ~mask))
        return f"instances cover {extra} pixels that the mask does not mark as target"
    return _check_meta(meta, int(inst.max()))


# --- writing ------------------------------------------------------------------------------


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


def _npy(a: np.ndarray) -> bytes:

    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=False)
    return buf.getvalue()


class _ShardWriter:
    """A USTAR tar written member by member (what :mod:`tarfile` writes), keeping each
    item's offsets and the CRC-32 of its bytes."""

    def __init__(self, path: Path) -> None:
        self.f = open(path, "xb")  # noqa: SIM115 - closed by close()
        self.pos = 0

    def _write(self, data: bytes, crc: int) -> int:
        self.f.write(data)
        self.pos += len(data)
        return zlib.crc32(data, crc)

    def add_item(self, key: str, members: list[bytes]) -> np.ndarray:
        """The item's members in order; returns its index rows."""
        rows = np.zeros((ROWS[VERSION], 2), np.int64)
        crc = 0
        for k, data in enumerate(members):
            info = tarfile.TarInfo(_member_name(key, k))
            info.size = len(data)
            crc = self._write(info.tobuf(tarfile.USTAR_FORMAT, "utf-8", "surrogateescape"), crc)
            rows[k] = (self.pos, len(data))
            crc = self._write(data, crc)
            pad = bytes(-len(data) % _BLOCK)
            if k < len(members) - 1:  # the item's bytes end with its last member's data
                crc = self._write(pad, crc)
            else:
                self._write(pad, 0)
        rows[-1] = (crc, 0)
        return rows

    def close(self) -> None:
        """The end-of-archive blocks, padded to a whole record as tarfile does."""
        end = self.pos + 2 * _BLOCK
        self.f.write(bytes(end - self.pos + (-end % tarfile.RECORDSIZE)))
        self.f.close()


def _members(item: object, i: int) -> list[bytes]:
    """An item's five members, its contract checked (naming item ``i`` of the source)."""
    if not isinstance(item, dict):
        raise EvalError(f"item {i} of the source is a {type(item).__name__}, not an item dict")
    arrays = {}
    for f in FIELDS:
        if f in item:
            v = item[f]
            arrays[f] = np.asarray(v.cpu().numpy() if isinstance(v, torch.Tensor) else v)
    meta = _jsonable(item.get("meta", {}))
    problem = check_item(arrays, meta)
    if problem:
        name = meta.get("name") if isinstance(meta, dict) else None
        what = f"item {i}" + (f" ({name})" if name is not None else "")
        raise EvalError(f"{what} of the source breaks the item contract: {problem}")
    return [*(_npy(arrays[f]) for f in FIELDS), json.dumps(meta).encode()]


def lock_path(out: str | Path) -> Path:
    """The lock file a writer of the store ``out`` holds: ``.<name>.store-lock`` beside it."""
    out = Path(out)
    return out.with_name(f".{out.name}{_LOCK}")


def partial_path(out: str | Path) -> Path:
    """Where the store ``out`` is built: ``.<name>.store-partial`` beside it."""
    out = Path(out)
    return out.with_name(f".{out.name}{_PARTIAL}")


def remove_dead_partials(parent: str | Path) -> list[Path]:
    """Remove the partial stores in ``parent`` whose writer is dead (its lock is free:
    see :mod:`torchsar_eval.locks`), with their lock files; returns the removed folders.
    Partial stores being written (lock held) are left alone."""
    parent = Path(parent)
    names = set()
    for p in parent.glob(".*.store-*"):
        for suffix in (_PARTIAL, _LOCK):
            if p.name.endswith(suffix):
                names.add(p.name[1 : -len(suffix)])
    removed = []
    for name in sorted(names):
        target = parent / name
        try:
            with hold(lock_path(target)):
                partial = partial_path(target)
                if partial.is_dir() and not partial.is_symlink():
                    shutil.rmtree(partial)
                    removed.append(partial)
                elif partial.exists() or partial.is_symlink():
                    partial.unlink()
        except LockHeldError:
            continue  # a live writer
    return removed


def _whole(value: object) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _check_counts(n: object, shard_size: object) -> None:
    if not _whole(n) or n < 0:
        raise EvalError(f"{{opt:n}}{_short(n)}: must be a whole number >= 0")
    if not _whole(shard_size) or shard_size < 1:
        raise EvalError(f"{{opt:shard_size}}{_short(shard_size)}: must be a whole number >= 1")


def write_store(
    items: Iterable[dict], n: int, out: Path, *, shard_size: int = 1000, info: dict | None = None
) -> Path:
    """Write ``n`` items into a new store folder ``out`` (built beside it, then renamed).

    Raises:
        EvalError: ``out`` exists, another process is writing it, the source gives fewer
            than ``n`` items, or an item breaks the item contract (named by its index).
    """
    _check_counts(n, shard_size)
    n, shard_size, out = int(n), int(shard_size), Path(out)
    exists = f"--out {out} already exists; choose a new folder"
    if out.exists() or out.is_symlink():
        raise EvalError(exists)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise EvalError(f"--out {out}: cannot create {out.parent} ({exc.strerror})") from None
    if not os.access(out.parent, os.W_OK | os.X_OK):
        raise EvalError(f"--out {out}: cannot write in {out.parent} (permission denied)")
    busy = (
        f"--out {out} is being written by another make-dataset (it holds "
        f"{lock_path(out).name}); wait for it to finish or choose another folder"
    )
    with hold(lock_path(out), wait=LOCK_WAIT_S, message=busy):
        if out.exists() or out.is_symlink():  # the other writer finished meanwhile
            raise EvalError(exists)
        remove_dead_partials(out.parent)  # the other dead writers' partial stores
        tmp = partial_path(out)
        if tmp.is_dir() and not tmp.is_symlink():  # ours, from a killed writer: we hold its
            shutil.rmtree(tmp)  # lock now, so nobody writes it (our own lock is not free to
        elif tmp.exists() or tmp.is_symlink():  # remove_dead_partials)
            tmp.unlink()
        tmp.mkdir()
        try:
            try:
                _write_folder(tmp, items, n, shard_size, info or {})
            except OSError as exc:  # a full disk, a quota: one line, nothing kept
                raise EvalError(
                    f"--out {out}: cannot write the store ({exc.strerror or exc}); nothing was kept"
                ) from None
            try:
                os.rename(tmp, out)
            except OSError as exc:
                raise EvalError(
                    f"--out {out} was filled by another process while the store was "
                    f"written ({exc.strerror}); choose a new folder"
                ) from None
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
    return out


def _write_folder(tmp: Path, items: Iterable[dict], n: int, shard_size: int, info: dict) -> None:
    index = np.zeros((n, ROWS[VERSION], 2), dtype=np.int64)
    it = iter(items)
    for k, start in enumerate(range(0, n, shard_size)):
        shard = _ShardWriter(tmp / f"shard-{k:06d}.tar")
        try:
            for i in range(start, min(start + shard_size, n)):
                item = next(it, _DROP)
                if item is _DROP:
                    raise EvalError(f"the source ended after {i} of the {n} items")
                index[i] = shard.add_item(f"{i:09d}", _members(item, i))
        finally:
            shard.close()
    np.save(tmp / "index.npy", index)
    header = {
        "format": FORMAT,
        "version": VERSION,
        "n": n,
        "shard_size": shard_size,
        "fields": list(MEMBERS),
        "checksum": "crc32 of each item's bytes (index row 5)",
    }
    header.update({k: v for k, v in info.items() if k not in header})
    (tmp / "store.json").write_text(json.dumps(header, indent=2, default=str) + "\n")


# --- reading ------------------------------------------------------------------------------


def _read_header(head: Path) -> dict:
    """``store.json``, checked: a JSON object of this format, whole-number counts."""
    data = read_small(head, HEADER_LIMIT, "store header")
    try:
        header = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise EvalError(f"{head}: not valid JSON ({reason[:80]})") from None
    if not isinstance(header, dict):
        kind = {list: "list", str: "string", int: "number", float: "number", bool: "boolean"}
        got = kind.get(type(header), "null")
        raise EvalError(f"{head}: expected a JSON object (the store header), got a {got}")
    fmt, version = header.get("format"), header.get("version")
    if fmt != FORMAT or type(version) is not int or version not in ROWS:
        raise EvalError(
            f"{head}: not a {FORMAT} header of version {' or '.join(map(str, ROWS))} "
            f"(format={_short(fmt)}, version={_short(version)})"
        )
    for key, least in (("n", 0), ("shard_size", 1)):
        if key not in header:
            raise EvalError(f"{head}: {key} is missing")
        v = header[key]
        if type(v) is not int or v < least:
            raise EvalError(f"{head}: {key}={_short(v)} must be a whole number >= {least}")
    return header


def _load_index(path: Path, mmap: bool) -> np.ndarray:
    require_regular(path, "store index")
    with open(path, "rb") as f:
        if f.read(6) != b"\x93NUMPY":
            raise EvalError(f"{path}: not a .npy file (it does not start with the NumPy magic)")
    try:
        return np.load(path, mmap_mode="r" if mmap else None, allow_pickle=False)
    except Exception as exc:  # numpy raises many types for a broken file: name it
        reason = (str(exc).splitlines() or [type(exc).__name__])[0][:80]
        raise EvalError(f"{path}: not a readable .npy index ({reason})") from None


def _check_index(root: Path, header: dict) -> tuple[int, ...]:
    """Every row of ``index.npy`` against its shard; returns the index's shape."""
    n, size_k, version = header["n"], header["shard_size"], header["version"]
    path = root / "index.npy"
    index = _load_index(path, mmap=True)
    if index.dtype != np.int64:
        raise EvalError(f"{path}: dtype {index.dtype}, expected int64 offsets")
    if index.ndim != 3 or index.shape[1:] != (ROWS[version], 2):
        raise EvalError(
            f"{path}: shape {index.shape}, expected (n, {ROWS[version]}, 2) "
            f"for a version {version} store"
        )
    if len(index) != n:
        raise EvalError(
            f"{root / 'store.json'}: n={n} but index.npy has {len(index)} rows "
            "(n must equal the index length)"
        )
    index = np.array(index[:, : len(MEMBERS)])
    shards = [root / f"shard-{k:06d}.tar" for k in range(-(-n // size_k))]
    sizes = np.array([require_regular(p, "store shard").st_size for p in shards], np.int64)
    shard_of = np.arange(n) // size_k
    off, size = index[..., 0], index[..., 1]
    limit = sizes[shard_of][:, None] if n else np.zeros((0, 1), np.int64)

    def row(i: int) -> str:
        return f"{path}: row {i} (item {i:09d})"

    bad = (off < _BLOCK) | (off % _BLOCK != 0) | (size < 0)
    past = ~bad & ((off > limit) | (size > limit) | (off + size > limit))
    if bad.any() or past.any():
        i, k = (int(v) for v in np.argwhere(bad | past)[0])
        o, s, tar = int(off[i, k]), int(size[i, k]), shards[shard_of[i]]
        if past[i, k]:
            raise EvalError(
                f"{row(i)}: member {MEMBERS[k]} at byte {o:,} of {s:,} bytes "
                f"ends past the end of {tar.name} ({sizes[shard_of[i]]:,} bytes: "
                "truncated, or not the shard this index was written with)"
            )
        raise EvalError(
            f"{row(i)}: member {MEMBERS[k]} at byte {o:,} of {s:,} bytes is no "
            f"place for a tar member of {tar.name}"
        )
    follows = off[:, 1:] == off[:, :-1] + size[:, :-1] + (-size[:, :-1] % _BLOCK) + _BLOCK
    if not follows.all():
        i, k = (int(v) for v in np.argwhere(~follows)[0])
        raise EvalError(
            f"{row(i)}: member {MEMBERS[k + 1]} does not follow member "
            f"{MEMBERS[k]} in {shards[shard_of[i]].name}"
        )
    start, end = off[:, 0] - _BLOCK, off[:, -1] + size[:, -1]
    for k, tar in enumerate(shards):
        rows = np.arange(k * size_k, min(n, (k + 1) * size_k))
        order = rows[np.argsort(start[rows], kind="stable")]
        clash = np.flatnonzero(start[order[1:]] < end[order[:-1]])
        if clash.size:
            a, b = sorted((int(order[clash[0]]), int(order[clash[0] + 1])))
            same = np.array_equal(index[a], index[b])
            how = "point to the same bytes of" if same else "overlap in"
            raise EvalError(
                f"{path}: rows {a} and {b} {how} {tar.name} (each item must "
                "have bytes of its own: one would be read twice)"
            )
    return (n, ROWS[version], 2)


def _tar_header(block: memoryview) -> tuple[str, int | None]:
    """Name and size of a USTAR header block (the two fields a read checks; the header's
    own checksum is left to the item's CRC-32); ``("?", None)`` if it has none."""
    raw = bytes(block)
    if len(raw) != _BLOCK:
        return "?", None
    name = raw[:100].split(b"\0", 1)[0].decode("utf-8", "replace")
    try:
        size = int(raw[124:136].strip(b"\0 ") or b"x", 8)
    except ValueError:
        size = None
    return name, size


class StoreDataset(Dataset):
    """A store written by :func:`write_store`, read lazily item by item (``store:PATH``).

    Raises:
        EvalError: on opening, a damaged header, index or shard (see the module docstring);
            :class:`BadItemError` naming the shard when an item is read damaged.
    """

    def __init__(self, root: str | Path, *, limit: int | None = None) -> None:
        self.root = Path(root)
        head = self.root / "store.json"
        if not (os.path.lexists(head) and self.root.is_dir()):
            raise EvalError(f"{self.root} is not a torchsar store (no store.json)")
        self.header = _read_header(head)
        self.version = int(self.header["version"])
        if limit is not None and (not _whole(limit) or limit < 0):
            raise EvalError(f"{{opt:n}}{_short(limit)}: must be a whole number >= 0")
        self._shape = _check_index(self.root, self.header)
        n = int(self.header["n"])
        self.n = n if limit is None else min(limit, n)
        self._index: np.ndarray | None = None  # mapped on first access (after any fork)
        self.name = f"store:{root}"
        self.options = {"root": str(self.root), "limit": limit, "source": self.header}

    def __len__(self) -> int:
        return self.n

    def _rows(self, i: int) -> np.ndarray:
        if self._index is None:
            index = _load_index(self.root / "index.npy", mmap=True)
            if index.shape != self._shape or index.dtype != np.int64:
                raise EvalError(f"{self.root / 'index.npy'}: changed since the store was opened")
            self._index = index
        return np.array(self._index[i])

    def _bad(self, shard: Path, key: str, problem: str) -> BadItemError:
        return BadItemError(str(shard), f"{shard}: item {key}: {problem}")

    def _read(self, shard: Path, key: str, rows: np.ndarray) -> bytes:
        """The item's bytes: from its first member's tar header to the end of its last
        member (they are consecutive in the tar), checked against the CRC-32."""
        first, end = int(rows[0, 0]) - _BLOCK, int(rows[len(MEMBERS) - 1].sum())
        size = require_regular(shard, "store shard").st_size
        if not 0 <= first < end <= size:  # checked on opening; the files changed since
            raise self._bad(
                shard,
                key,
                f"its index row (bytes {first:,} to {end:,}) does not "
                f"fit the shard's {size:,} bytes: the store changed since it was "
                "opened",
            )
        with open(shard, "rb") as f:
            f.seek(first)
            data = f.read(end - first)
        if len(data) != end - first:
            raise self._bad(shard, key, f"the shard is truncated (item ends at byte {end:,})")
        if self.version >= 2 and zlib.crc32(data) != int(rows[len(MEMBERS), 0]):
            raise self._bad(
                shard, key, "checksum mismatch: its bytes changed since the store was written"
            )
        return data

    def __getitem__(self, i: int) -> dict:
        if not 0 <= i < self.n:
            raise IndexError(i)
        rows = self._rows(i)
        shard = self.root / f"shard-{i // int(self.header['shard_size']):06d}.tar"
        key = f"{i:09d}"
        data = memoryview(self._read(shard, key, rows))
        first = int(rows[0, 0]) - _BLOCK
        parts = []
        for k in range(len(MEMBERS)):
            o, s = int(rows[k, 0]) - first, int(rows[k, 1])
            want = _member_name(key, k)
            name, size = _tar_header(data[o - _BLOCK : o])
            if name != want or size != s:
                raise self._bad(
                    shard,
                    key,
                    f"the index points to member {_short(name)} of {size} bytes, not {want} of {s}",
                )
            parts.append(data[o : o + s])
        arrays = {}
        for f, part in zip(FIELDS, parts, strict=False):
            try:
                arrays[f] = read_npy(part)
            except NpyError as exc:
                raise self._bad(shard, key, f"{f}.npy: {exc}") from None
        try:
            meta = json.loads(bytes(parts[-1]).decode("utf-8"))
        except (UnicodeDecodeError, ValueError, RecursionError) as exc:
            raise self._bad(shard, key, f"{key}.json is not valid JSON ({exc})") from None
        problem = check_item(arrays, meta)
        if problem:
            raise self._bad(shard, key, problem)
        out = {f: torch.from_numpy(arrays[f]) for f in FIELDS}
        out["meta"] = meta
        return out

    def manifest(self) -> dict:
        """Files, bytes and the store header (the store is the data's identity)."""
        files = sorted(p for p in self.root.iterdir() if p.is_file())
        return {
            "files": len(files),
            "bytes": sum(p.stat().st_size for p in files),
            "header": self.header,
        }

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["_index"] = None  # never ship the memory map to a worker
        return state
