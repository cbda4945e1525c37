"""MSTAR "Phoenix" files: an ASCII header, then big-endian float32 magnitude and phase.

The header opens with ``[PhoenixHeaderVer01.04]`` (after an optional newline), gives its
own length in ``PhoenixHeaderLength= 01977`` and ends with ``[EndofPhoenixHeader]``; the
data follow at that offset: ``rows x cols`` magnitudes, then ``rows x cols`` phases in
radians. The image size is ``NumberOfRows`` x ``NumberOfColumns``; the pixel spacing is
``RangePixelSpacing`` (rows: the radar looks up the image) x ``CrossRangePixelSpacing``
(columns), in metres.

Reference: MSTAR public release (AFRL/SDMS), file format description of the Phoenix header.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from torchsar.io.errors import FileFormatError
from torchsar.io.raster import DEFAULT_MAX_PIXELS, check_regular_file

__all__ = ["PhoenixChip", "is_phoenix", "read_phoenix", "read_phoenix_header"]

MAGIC = b"[PhoenixHeaderVer"
_MAX_HEADER = 1 << 16


@dataclass(frozen=True)
class PhoenixChip:
    """One MSTAR chip.

    Attributes:
        magnitude: ``(rows, cols)`` float32 linear magnitude.
        phase: ``(rows, cols)`` float32 phase in radians.
        header: every ``key= value`` field of the header, as strings.
        pixel_spacing: ``(row_m, col_m)`` or ``None`` when the header has no spacing.
    """

    magnitude: np.ndarray
    phase: np.ndarray
    header: dict[str, str]
    pixel_spacing: tuple[float, float] | None

    @property
    def complex(self) -> np.ndarray:
        """The complex samples ``magnitude * exp(1j * phase)`` (complex64)."""
        return (self.magnitude * np.exp(1j * self.phase)).astype(np.complex64)


def is_phoenix(path: str | Path) -> bool:
    """Whether a regular file starts with the Phoenix header tag."""
    if not os.path.isfile(path):
        return False
    with open(path, "rb") as f:
        return f.read(len(MAGIC) + 1).lstrip(b"\r\n").startswith(MAGIC)


def read_phoenix_header(path: str | Path) -> dict[str, str]:
    """The header fields (``key= value`` lines) of a Phoenix file.

    Raises:
        FileFormatError: not a Phoenix file, or no ``PhoenixHeaderLength``.
    """
    check_regular_file(path)
    with open(path, "rb") as f:
        head = f.read(_MAX_HEADER)
    if not head.lstrip(b"\r\n").startswith(MAGIC):
        raise FileFormatError(path, "is not an MSTAR Phoenix file (no [PhoenixHeaderVer tag)")
    end = head.find(b"[EndofPhoenixHeader]")
    text = head[: end if end >= 0 else len(head)].decode("ascii", errors="replace")
    fields = {}
    for line in text.splitlines():
        key, sep, value = line.partition("=")
        if sep:
            fields[key.strip()] = value.strip()
    if "PhoenixHeaderLength" not in fields:
        raise FileFormatError(path, "Phoenix header has no PhoenixHeaderLength field")
    return fields


def _int_field(fields: dict[str, str], key: str, path: str | Path) -> int:
    """A positive integer header field, or an error naming the file and the field."""
    try:
        value = int(fields[key])
    except (KeyError, ValueError):
        raise FileFormatError(
            path, f"Phoenix header field {key} is missing or not an integer"
        ) from None
    if value <= 0:
        raise FileFormatError(path, f"Phoenix header field {key} is {value}; must be > 0")
    return value


def _spacing(fields: dict[str, str]) -> tuple[float, float] | None:
    """``(RangePixelSpacing, CrossRangePixelSpacing)`` when both parse as positive floats."""
    try:
        sp = (float(fields["RangePixelSpacing"]), float(fields["CrossRangePixelSpacing"]))
    except (KeyError, ValueError):
        return None
    return sp if min(sp) > 0 else None


def read_phoenix(path: str | Path, *, max_pixels: int = DEFAULT_MAX_PIXELS) -> PhoenixChip:
    """Read an MSTAR Phoenix file; the header's size must match the file exactly.

    Args:
        path: the file.
        max_pixels: largest ``rows * cols`` accepted (checked before reading the data).

    Raises:
        FileFormatError: not Phoenix, a header that lies about the size (data shorter or
            longer than ``2 * rows * cols`` float32), or an image over ``max_pixels``.
    """
    fields = read_phoenix_header(path)
    offset = _int_field(fields, "PhoenixHeaderLength", path)
    rows = _int_field(fields, "NumberOfRows", path)
    cols = _int_field(fields, "NumberOfColumns", path)
    if rows * cols > max_pixels:
        raise FileFormatError(
            path, f"Phoenix header declares {cols}x{rows} pixels, over max_pixels={max_pixels:,}"
        )
    data_bytes = os.path.getsize(path) - offset
    if data_bytes != 2 * rows * cols * 4:
        raise FileFormatError(
            path,
            f"Phoenix header says {rows}x{cols} (magnitude + phase = {8 * rows * cols} bytes) "
            f"but the file holds {data_bytes} bytes after its {offset}-byte header",
        )
    data = np.fromfile(path, dtype=">f4", count=2 * rows * cols, offset=offset)
    data = data.astype(np.float32).reshape(2, rows, cols)
    return PhoenixChip(data[0], data[1], fields, _spacing(fields))
