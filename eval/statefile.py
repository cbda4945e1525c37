"""State files that hold data only: a run's saved shard states are read back without running
any code from them.

A state file is a line naming the format, a JSON header line (format, version and a BLAKE2b
hash of the body) and the body: zlib-compressed, the length of a JSON structure (8 bytes,
little-endian), the structure, and the state's arrays as raw bytes, each at a 64-byte
aligned offset. The structure holds a table of the arrays (offset, plain numeric type,
shape) and the state as JSON (plain values, references to the arrays, and the names of the
classes to rebuild). Reading checks the format, the version and the hash, copies each array
out of the decompressed bytes (only boolean, numeric and record types, inside the body) and
rebuilds only the classes of an allow-list (the harness's result and metric states) by
setting their attributes: a file can hold wrong numbers at worst, and a changed or
truncated file is refused as corrupt. Version 1 files (the body an NPZ archive read with
``allow_pickle=False``) are still read.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import torch

from torchsar_eval.errors import EvalError

__all__ = [
    "FORMAT",
    "VERSION",
    "CorruptStateError",
    "decode",
    "dumps",
    "encode",
    "loads",
    "pack",
    "register",
    "save",
    "unpack",
]

FORMAT = "torchsar-state"
VERSION = 2
READABLE = (1, 2)  # versions read back (1: the body an NPZ archive)

_TYPES: dict[str, type] = {}
_TRANSIENT: dict[str, tuple[str, ...]] = {}


class CorruptStateError(EvalError):
    """A state file that is not a complete, unchanged torchsar state."""


def _key(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def register(cls: type, *, transient: tuple[str, ...] = ()) -> type:
    """Allow ``cls`` in state files, named by its module and name (``transient``: attributes
    not saved, ``None`` when read back). Its state is ``__getstate__()`` when it defines
    one, else its attributes."""
    _TYPES[_key(cls)] = cls
    _TRANSIENT[_key(cls)] = transient
    return cls


def _own(cls: type, name: str) -> bool:
    return getattr(cls, name, None) is not getattr(object, name, None)


class _Encoder:
    def __init__(self) -> None:
        self.arrays: list[np.ndarray] = []

    def array(self, a: np.ndarray, kind: str) -> dict:
        """``{kind: key}`` for an array stored under ``key``; a wide integer array whose values
        fit a narrower integer type is stored in it, with its own dtype named beside the key
        (the counts of a shard, held in int64, are mostly small: 8 times fewer bytes to
        compress, write and read)."""
        if a.dtype.hasobject:
            raise TypeError("object arrays cannot be saved as data")
        out: dict[str, Any] = {}
        narrow = _narrow(a)
        if narrow is not None:
            out["__as__"] = np.lib.format.dtype_to_descr(a.dtype)
            a = a.astype(narrow)
        out[kind] = self._put(a)
        return out

    def _put(self, a: np.ndarray) -> int:
        self.arrays.append(np.require(a, requirements="C"))  # keeps 0-d arrays 0-d
        return len(self.arrays) - 1

    def __call__(self, obj: Any) -> Any:
        if obj is None or isinstance(obj, bool | int | float | str):
            return obj
        if isinstance(obj, np.generic):
            return obj.item()
        if isinstance(obj, np.dtype):
            return {"__dtype__": self(np.lib.format.dtype_to_descr(obj))}
        if isinstance(obj, np.ndarray):
            return self.array(obj, "__array__")
        if isinstance(obj, torch.Tensor):
            return self.array(obj.detach().cpu().numpy(), "__tensor__")
        if isinstance(obj, list):
            return [self(v) for v in obj]
        if isinstance(obj, tuple):
            return {"__tuple__": [self(v) for v in obj]}
        if isinstance(obj, dict):
            return {"__dict__": [[self(k), self(v)] for k, v in obj.items()]}
        name = _key(type(obj))
        if _TYPES.get(name) is not type(obj):
            raise TypeError(f"{type(obj).__name__} is not a state type")
        if _own(type(obj), "__getstate__"):
            state = obj.__getstate__()
        else:
            state = {k: v for k, v in vars(obj).items() if k not in _TRANSIENT[name]}
        return {"__type__": name, "state": self(state)}


_NARROW = (np.int8, np.int16, np.int32)


def _narrow(a: np.ndarray) -> np.dtype | None:
    """The narrowest signed integer type holding every value of a 64-bit integer array, when
    narrower than its own (``None``: stored as it is)."""
    if a.dtype.kind not in "iu" or a.dtype.itemsize != 8 or a.size == 0:
        return None
    lo, hi = int(a.min()), int(a.max())
    for t in _NARROW:
        info = np.iinfo(t)
        if info.min <= lo and hi <= info.max:
            return np.dtype(t)
    return None


def _stored(tree: dict, kind: str, arrays: list | dict) -> np.ndarray:
    """The array a ``{kind: key}`` node refers to, in its own dtype again when it was stored
    narrower (``__as__``; only a widening to a 64-bit integer type is accepted)."""
    if not set(tree) <= {kind, "__as__"}:
        raise ValueError("unexpected array node")
    a = arrays[tree[kind]]
    if "__as__" not in tree:
        return a.copy()  # its own memory, writable
    dtype = np.lib.format.descr_to_dtype(tree["__as__"])
    if dtype.kind not in "iu" or dtype.itemsize != 8 or a.dtype.kind != "i":
        raise ValueError(f"unexpected stored type {tree['__as__']!r}")
    return a.astype(dtype)


def _decode(tree: Any, arrays: list | dict) -> Any:
    if tree is None or isinstance(tree, bool | int | float | str):
        return tree
    if isinstance(tree, list):
        return [_decode(v, arrays) for v in tree]
    if not isinstance(tree, dict):
        raise ValueError("unexpected structure")
    if "__array__" in tree:
        return _stored(tree, "__array__", arrays)
    if "__tensor__" in tree:
        return torch.from_numpy(_stored(tree, "__tensor__", arrays))
    if len(tree) not in (1, 2):
        raise ValueError("unexpected structure")
    if "__dtype__" in tree:
        return np.lib.format.descr_to_dtype(_decode(tree["__dtype__"], arrays))
    if "__tuple__" in tree:
        return tuple(_decode(v, arrays) for v in tree["__tuple__"])
    if "__dict__" in tree:
        return {_decode(k, arrays): _decode(v, arrays) for k, v in tree["__dict__"]}
    cls = _TYPES[tree["__type__"]]  # KeyError for any type off the allow-list
    state = _decode(tree["state"], arrays)
    obj = cls.__new__(cls)
    if _own(cls, "__setstate__"):
        obj.__setstate__(state)
    else:
        obj.__dict__.update({k: None for k in _TRANSIENT[tree["__type__"]]})
        obj.__dict__.update(state)
    return obj


MAGIC = b"torchsar-state\n"


def _digest(body: bytes) -> str:
    return hashlib.blake2b(body, digest_size=32).hexdigest()


_ALIGN = 64
_LENGTH = 8  # bytes of the structure's length
_DESCR = re.compile(r"[<>|][biufc][0-9]{1,2}\Z")  # booleans and plain numbers only
_PAD = re.compile(r"\|V[0-9]{1,4}\Z")


def _aligned(n: int) -> int:
    return -(-n // _ALIGN) * _ALIGN


def pack(structure: Any, arrays: list[np.ndarray]) -> bytes:
    """The uncompressed body of a version-2 file: ``structure`` (JSON-able) with the
    table of ``arrays`` (C-contiguous) under ``"arrays"``, then their bytes."""
    table, offset = [], 0
    for a in arrays:
        table.append([offset, np.lib.format.dtype_to_descr(a.dtype), list(a.shape)])
        offset = _aligned(offset + a.nbytes)
    head = json.dumps({"arrays": table, "tree": structure}, separators=(",", ":")).encode()
    start = _aligned(_LENGTH + len(head))
    raw = bytearray(start + offset)
    raw[:_LENGTH] = len(head).to_bytes(_LENGTH, "little")
    raw[_LENGTH : _LENGTH + len(head)] = head
    data = np.frombuffer(raw, np.uint8)
    for (at, _, _), a in zip(table, arrays, strict=True):
        data[start + at : start + at + a.nbytes] = a.reshape(-1).view(np.uint8)
    return bytes(raw)


def unpack(raw: bytes) -> tuple[Any, list[np.ndarray]]:
    """``(structure, arrays)`` of a version-2 body; the arrays are read-only views of
    ``raw`` (:func:`loads` copies each out, so no kept array holds the whole body alive).
    ``ValueError`` for anything but a well-formed table of plain arrays inside the body."""
    n = int.from_bytes(raw[:_LENGTH], "little")
    if len(raw) < _LENGTH + n:
        raise ValueError("truncated structure")
    head = json.loads(raw[_LENGTH : _LENGTH + n])
    if not isinstance(head, dict) or set(head) != {"arrays", "tree"}:
        raise ValueError("unexpected structure")
    start = _aligned(_LENGTH + n)
    return head["tree"], [_view(raw, start, entry) for entry in _entries(head["arrays"])]


def _entries(table: Any) -> list:
    if not isinstance(table, list) or not all(isinstance(e, list) and len(e) == 3 for e in table):
        raise ValueError("unexpected array table")
    return table


def _view(data: bytes, start: int, entry: list) -> np.ndarray:
    offset, descr, shape = entry
    if not _plain(descr):
        raise ValueError(f"unexpected array type {descr!r}")
    if not (_dims(shape) and type(offset) is int and offset >= 0):
        raise ValueError("unexpected array shape or offset")
    dtype = np.lib.format.descr_to_dtype(_as_descr(descr))
    count = int(np.prod(shape, dtype=np.int64))
    if start + offset + count * dtype.itemsize > len(data):
        raise ValueError("an array reaches past the end of the body")
    return np.frombuffer(data, dtype, count, start + offset).reshape(shape)


def _plain(descr: Any) -> bool:
    """A boolean or numeric type, or a record of them (``[name, type(, shape)]`` fields;
    unnamed fields are padding)."""
    if isinstance(descr, str):
        return bool(_DESCR.match(descr))
    return isinstance(descr, list) and all(
        isinstance(f, list)
        and len(f) in (2, 3)
        and isinstance(f[0], str)
        and (_plain(f[1]) or (f[0] == "" and isinstance(f[1], str) and _PAD.match(f[1])))
        and (len(f) == 2 or _dims(f[2]))
        for f in descr
    )


def _dims(shape: Any) -> bool:
    """A JSON shape: a list of non-negative integers."""
    return isinstance(shape, list) and all(type(d) is int and d >= 0 for d in shape)


def _as_descr(descr: Any) -> Any:
    """JSON's lists back into the tuples of numpy's record descriptions."""
    if isinstance(descr, str):
        return descr
    return [
        (f[0], _as_descr(f[1])) if len(f) == 2 else (f[0], _as_descr(f[1]), tuple(f[2]))
        for f in descr
    ]


def encode(obj: Any) -> tuple[Any, list[np.ndarray]]:
    """``(structure, arrays)`` of ``obj``: plain JSON values and numpy arrays, what a state
    file holds before it is packed (an in-memory state, e.g. a ``state_dict``)."""
    enc = _Encoder()
    return enc(obj), enc.arrays


def decode(tree: Any, arrays: list[np.ndarray], what: str = "state") -> Any:
    """The object of :func:`encode`'s ``(structure, arrays)``, rebuilt from the allow-list
    only; :class:`CorruptStateError` (naming ``what``) for anything else."""
    try:
        checked = [np.asarray(a) for a in arrays]
        if any(a.dtype.hasobject for a in checked):
            raise ValueError("object arrays are not data")
        return _decode(tree, checked)
    except (ValueError, KeyError, TypeError, IndexError) as exc:
        raise CorruptStateError(f"{what} holds an unexpected structure ({exc})") from None


def dumps(obj: Any) -> bytes:
    """The bytes of a state file holding ``obj`` (see the module docstring)."""
    enc = _Encoder()
    tree = enc(obj)
    body = zlib.compress(pack(tree, enc.arrays), 1)
    header = {"format": FORMAT, "version": VERSION, "blake2b": _digest(body)}
    return MAGIC + json.dumps(header).encode() + b"\n" + body


def loads(data: bytes, what: str = "state") -> Any:
    """The object a state file holds; :class:`CorruptStateError` (naming ``what``) when it is
    not a complete, unchanged state of this format and a readable version."""
    if not data.startswith(MAGIC) or b"\n" not in data[len(MAGIC) :]:
        raise CorruptStateError(f"{what} is not a readable torchsar state (no {FORMAT} header)")
    line, _, body = data[len(MAGIC) :].partition(b"\n")
    try:
        header = json.loads(line)
    except (ValueError, UnicodeDecodeError):
        raise CorruptStateError(f"{what} is not a readable torchsar state (bad header)") from None
    version = header.get("version") if isinstance(header, dict) else None
    if not isinstance(header, dict) or header.get("format") != FORMAT or version not in READABLE:
        raise CorruptStateError(f"{what} is not a {FORMAT} version {VERSION} file")
    if header.get("blake2b") != _digest(body):
        raise CorruptStateError(f"{what} has changed since it was written (content hash mismatch)")
    try:
        tree, arrays = (unpack if version == 2 else _unpack_npz)(zlib.decompress(body))
        return _decode(tree, arrays)
    except (
        zlib.error,
        ValueError,
        KeyError,
        TypeError,
        IndexError,
        OSError,
        zipfile.BadZipFile,
        EOFError,
    ) as exc:
        raise CorruptStateError(f"{what} holds an unexpected structure ({exc})") from None


def _unpack_npz(raw: bytes) -> tuple[Any, dict[str, np.ndarray]]:
    """``(structure, arrays)`` of a version-1 body (an NPZ archive, read without pickle)."""
    with np.load(io.BytesIO(raw), allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    return json.loads(arrays.pop("__structure__").tobytes()), arrays


def save(path: Path, data: bytes) -> None:
    """Write state bytes atomically (a temporary name in the same folder, fsync, rename):
    a reader sees the whole file or none. :class:`EvalError` naming the file when it cannot
    be saved (a full disk): no fault of the state's."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        reason = exc.strerror or exc
        raise EvalError(f"cannot save {path.name} in {path.parent} ({reason})") from exc
