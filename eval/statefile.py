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

    def array(self, a: np.ndarray) -> str:
        if a.dtype.hasobject:
            raise TypeError("object arrays cannot be saved as data")
        key = f"a{len(self.arrays)}"
        self.arrays[key] = np.ascontiguousarray(a)
        return key

    def __call__(self, obj: Any) -> Any:
        if obj is None or isinstance(obj, bool | int | float | str):
            return obj
        if isinstance(obj, np.generic):
            return obj.item()
        if isinstance(obj, np.dtype):
            return {"__dtype__": self(np.lib.format.dtype_to_descr(obj))}
        if isinstance(obj, np.ndarray):
            return {"__array__": self.array(obj)}
        if isinstance(obj, torch.Tensor):
            return {"__tensor__": self.array(obj.detach().cpu().numpy())}
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


def _decode(tree: Any, arrays: dict[str, np.ndarray]) -> Any:
    if tree is None or isinstance(tree, bool | int | float | str):
        return tree
    if isinstance(tree, list):
        return [_decode(v, arrays) for v in tree]
    if not isinstance(tree, dict) or len(tree) not in (1, 2):
        raise ValueError("unexpected structure")
    if "__array__" in tree:
        return arrays[tree["__array__"]]
    if "__tensor__" in tree:
        return torch.from_numpy(np.array(arrays[tree["__tensor__"]]))
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
