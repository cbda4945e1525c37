"""``.npy`` bytes to arrays, with each distinct header parsed once.

``numpy.load`` parses every header with ``ast.literal_eval``, which costs more than copying
a 128 x 128 chip. A store's members share a handful of headers (one per field and image
size), so the parse is cached by the header text; the rest is a copy of the data bytes.
"""

from __future__ import annotations

import ast
import struct
from functools import lru_cache

import numpy as np

__all__ = ["read_npy"]

_MAGIC = b"\x93NUMPY"


@lru_cache(maxsize=256)
def _header(text: bytes) -> tuple[np.dtype, tuple[int, ...], bool]:
    """dtype, shape and Fortran order of a header dict (no object arrays)."""
    d = ast.literal_eval(text.decode("latin1"))
    dtype = np.dtype(d["descr"])
    if dtype.hasobject:
        raise ValueError("object arrays are not read (they would need pickle)")
    return dtype, tuple(int(n) for n in d["shape"]), bool(d["fortran_order"])


def read_npy(data: bytes | memoryview) -> np.ndarray:
    """The array of one ``.npy`` file's bytes (format versions 1 to 3), as a writable copy.

    Raises:
        ValueError: not ``.npy`` bytes, truncated data or an object dtype.

    Example:
        >>> import io
        >>> buf = io.BytesIO(); np.save(buf, np.arange(6).reshape(2, 3))
        >>> read_npy(buf.getvalue()).tolist()
        [[0, 1, 2], [3, 4, 5]]
    """
    data = memoryview(data)
    if bytes(data[:6]) != _MAGIC or data[6] not in (1, 2, 3):
        raise ValueError("not .npy bytes")
    fmt, start = ("<H", 10) if data[6] == 1 else ("<I", 12)
    (size,) = struct.unpack(fmt, data[8:start])
    dtype, shape, fortran = _header(bytes(data[start : start + size]))
    body = data[start + size :]
    count = int(np.prod(shape, dtype=np.int64))
    if len(body) < count * dtype.itemsize:
        raise ValueError("truncated .npy data")
    flat = np.frombuffer(body, dtype=dtype, count=count).copy()
    return flat.reshape(shape, order="F" if fortran else "C")
