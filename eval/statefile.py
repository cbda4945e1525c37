"""State files that hold data only: a run's saved shard states are read back without running
any code from them.

A state file is a line naming the format, a JSON header line (format, version and a BLAKE2b
hash of the body) and the body: a zlib-compressed NPZ archive (``numpy.save`` without pickle)
of the state's arrays and of its structure as JSON (plain values, references to the arrays,
and the names of the classes to rebuild). Reading checks the format, the version and the
hash, loads the arrays with ``allow_pickle=False`` and rebuilds only the classes of an
allow-list (the harness's result and metric states) by setting their attributes: a file can
hold wrong numbers at worst, and a changed or truncated file is refused as corrupt.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import torch

from torchsar_eval.errors import EvalError

__all__ = ["FORMAT", "VERSION", "CorruptStateError", "dumps", "loads", "register", "save"]

FORMAT = "torchsar-state"
VERSION = 1

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
        self.arrays: dict[str, np.ndarray] = {}

    def array(self, a: np.ndarray, kind: str) -> dict:
        """``{kind: key}`` for an array stored under ``key``; a wide integer array whose values
        fit a narrower integer type is stored in it, with its own dtype named beside the key
        (the counts of a shard, held in int64, are mostly small: 8 times fewer bytes to
        compress, write and read)."""
        if a.dtype.hasobject:
            raise TypeError("object arrays cannot be saved as data")
        key = f"a{len(self.arrays)}"
        out: dict[str, Any] = {kind: key}
        narrow = _narrow(a)
        if narrow is not None:
            out["__as__"] = np.lib.format.dtype_to_descr(a.dtype)
            a = a.astype(narrow)
        self.arrays[key] = np.ascontiguousarray(a)
        return out

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


def _stored(tree: dict, kind: str, arrays: dict[str, np.ndarray]) -> np.ndarray:
    """The array a ``{kind: key}`` node refers to, in its own dtype again when it was stored
    narrower (``__as__``; only a widening to a 64-bit integer type is accepted)."""
    a = arrays[tree[kind]]
    if "__as__" not in tree:
        return a
    dtype = np.lib.format.descr_to_dtype(tree["__as__"])
    if dtype.kind not in "iu" or dtype.itemsize != 8 or a.dtype.kind != "i":
        raise ValueError(f"unexpected stored type {tree['__as__']!r}")
    return a.astype(dtype)


def _decode(tree: Any, arrays: dict[str, np.ndarray]) -> Any:
    if tree is None or isinstance(tree, bool | int | float | str):
        return tree
    if isinstance(tree, list):
        return [_decode(v, arrays) for v in tree]
    if not isinstance(tree, dict) or len(tree) not in (1, 2):
        raise ValueError("unexpected structure")
    if "__array__" in tree:
        return _stored(tree, "__array__", arrays)
    if "__tensor__" in tree:
        return torch.from_numpy(np.array(_stored(tree, "__tensor__", arrays)))
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


def dumps(obj: Any) -> bytes:
    """The bytes of a state file holding ``obj`` (see the module docstring)."""
    enc = _Encoder()
    structure = json.dumps(enc(obj), separators=(",", ":")).encode()
    buf = io.BytesIO()
    np.savez(buf, __structure__=np.frombuffer(structure, np.uint8), **enc.arrays)
    body = zlib.compress(buf.getvalue(), 1)
    header = {"format": FORMAT, "version": VERSION, "blake2b": _digest(body)}
    return MAGIC + json.dumps(header).encode() + b"\n" + body


def loads(data: bytes, what: str = "state") -> Any:
    """The object a state file holds; :class:`CorruptStateError` (naming ``what``) when it is
    not a complete, unchanged state of this format and version."""
    if not data.startswith(MAGIC) or b"\n" not in data[len(MAGIC) :]:
        raise CorruptStateError(f"{what} is not a readable torchsar state (no {FORMAT} header)")
    line, _, body = data[len(MAGIC) :].partition(b"\n")
    try:
        header = json.loads(line)
    except (ValueError, UnicodeDecodeError):
        raise CorruptStateError(f"{what} is not a readable torchsar state (bad header)") from None
    if not isinstance(header, dict) or (header.get("format"), header.get("version")) != (
            FORMAT, VERSION):  # fmt: skip
        raise CorruptStateError(f"{what} is not a {FORMAT} version {VERSION} file")
    if header.get("blake2b") != _digest(body):
        raise CorruptStateError(f"{what} has changed since it was written (content hash mismatch)")
    try:
        with np.load(io.BytesIO(zlib.decompress(body)), allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
        structure = json.loads(arrays.pop("__structure__").tobytes())
        return _decode(structure, arrays)
    except (zlib.error, ValueError, KeyError, TypeError, OSError, zipfile.BadZipFile,
            EOFError) as exc:  # fmt: skip
        raise CorruptStateError(f"{what} holds an unexpected structure ({exc})") from None


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
