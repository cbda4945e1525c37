"""``.npy`` bytes to arrays, with each distinct header parsed once.

``numpy.load`` parses every header with ``ast.literal_eval``, which costs more than copying
a 128 x 128 chip. A store's members share a handful of headers (one per field and image
size), so the parse is cached by the header text; the rest is a copy of the data bytes.
"""

from __future__ import annotations

import ast
import math
import struct
from functools import lru_cache

import numpy as np

__all__ = ["NpyError", "read_npy"]

_MAGIC = b"\x93NUMPY"


_MAX_HEADER = 65535  # numpy writes headers of a few hundred bytes


class NpyError(ValueError):
    """Bytes that are not a ``.npy`` array this reader accepts (the message says why)."""


@lru_cache(maxsize=256)
def _header(text: bytes) -> tuple[np.dtype, tuple[int, ...], bool]:
    """dtype, shape and Fortran order of a header dict (plain numeric and bool dtypes)."""
    try:
        d = ast.literal_eval(text.decode("latin1"))
    except (SyntaxError, ValueError, TypeError, MemoryError, RecursionError) as exc:
        raise NpyError(f"unreadable .npy header ({type(exc).__name__})") from None
    if not isinstance(d, dict) or set(d) != {"descr", "fortran_order", "shape"}:
        raise NpyError("a .npy header must be a dict of descr, fortran_order and shape")
    shape, fortran = d["shape"], d["fortran_order"]
    if not isinstance(shape, tuple) or not all(type(n) is int and 0 <= n < 2**62 for n in shape):
        raise NpyError(f".npy shape {shape!r} is not a tuple of sizes >= 0")
    if type(fortran) is not bool:
        raise NpyError(f".npy fortran_order {fortran!r} is not True or False")
    try:
        dtype = np.dtype(d["descr"]) if isinstance(d["descr"], str) else None
    except (TypeError, ValueError):
        dtype = None
    if dtype is None or dtype.kind not in "biufc" or dtype.shape or dtype.fields:
        what = "object arrays are not read (they would need pickle)"
        if dtype is None or not dtype.hasobject:
            what = f".npy dtype {d['descr']!r} is not a plain number or bool type"
        raise NpyError(what)
    return dtype, shape, fortran


def read_npy(data: bytes | memoryview) -> np.ndarray:
    """The array of one ``.npy`` file's bytes (format versions 1 to 3), as a writable copy.

    Raises:
        NpyError: (a ValueError) not ``.npy`` bytes, a bad header, a dtype other than
            bool, integer, float or complex, or data shorter or longer than the header says.

    Examples:
        >>> import io
        >>> buf = io.BytesIO(); np.save(buf, np.arange(6).reshape(2, 3))
        >>> read_npy(buf.getvalue()).tolist()
        [[0, 1, 2], [3, 4, 5]]
    """
    data = memoryview(data).cast("B")
    if len(data) < 10 or bytes(data[:6]) != _MAGIC or data[6] not in (1, 2, 3):
        raise NpyError("not .npy bytes")
    fmt, start = ("<H", 10) if data[6] == 1 else ("<I", 12)
    if len(data) < start:
        raise NpyError("truncated .npy header")
    (size,) = struct.unpack(fmt, data[8:start])
    if size > _MAX_HEADER or len(data) < start + size:
        raise NpyError(f"truncated or oversized .npy header ({size} bytes)")
    dtype, shape, fortran = _header(bytes(data[start : start + size]))
    body = data[start + size :]
    nbytes = math.prod(shape) * dtype.itemsize
    if len(body) != nbytes:
        what = "truncated" if len(body) < nbytes else "oversized"
        raise NpyError(f"{what} .npy data: {len(body):,} bytes for shape {shape} of {dtype}")
    flat = np.frombuffer(body, dtype=dtype).copy()
    return flat.reshape(shape, order="F" if fortran else "C")
