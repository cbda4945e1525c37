"""Raster files (PNG, JPEG, TIFF): header-first size checks, then a bounded decode.

Every reader here refuses what it must not open (FIFOs, devices: opening a FIFO blocks)
and checks the pixel count from the file header before decoding, so a small file that
declares a huge image costs nothing. tifffile's log messages about a damaged file are held
back while it is read here and become part of the error (they would otherwise be printed
on stderr, once per read). Arrays come back as stored: ``(H, W)`` or
``(H, W, C)`` channels-last, palette images as their indices, 16-bit as ``uint16``,
float and complex TIFF as stored.
"""

from __future__ import annotations

import logging
import os
import re
import stat
import threading
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from torchsar.io.errors import FileFormatError

__all__ = [
    "DEFAULT_MAX_PIXELS",
    "RASTER_EXTS",
    "TIFF_EXTS",
    "check_regular_file",
    "raster_shape",
    "read_raster",
    "tiff_dtype",
    "tifffile_log",
]

DEFAULT_MAX_PIXELS = 100_000_000
TIFF_EXTS = (".tif", ".tiff")
RASTER_EXTS = (".png", ".jpg", ".jpeg", *TIFF_EXTS)


def check_regular_file(path: str | Path) -> None:
    """Refuse anything but a regular file (FIFO, device, socket, folder) without opening it.

    Raises:
        FileFormatError: the path is missing or not a regular file.
    """
    try:
        mode = os.stat(path).st_mode
    except OSError as exc:
        raise FileFormatError(path, f"cannot be read ({exc.strerror})") from exc
    if not stat.S_ISREG(mode):
        raise FileFormatError(path, "is not a regular file (FIFO, device or folder); refused")


class _HeldBack(logging.Filter):
    """Keeps the records of the ``tifffile`` logger from its handlers on the threads that
    are inside :func:`tifffile_log`, collecting their messages there."""

    local = threading.local()

    def filter(self, record: logging.LogRecord) -> bool:
        held = getattr(self.local, "messages", None)
        if held is None:
            return True
        held.append(re.sub(r"^(<[^>]*>\s*)+", "", record.getMessage()))
        return False


_HELD_BACK = _HeldBack()


@contextmanager
def tifffile_log() -> Iterator[list[str]]:
    """Hold back tifffile's log messages on this thread while the block runs; yields the
    list they are collected in (for the error message of a file that fails).

    Examples:
        >>> import logging
        >>> with tifffile_log() as messages:
        ...     logging.getLogger("tifffile").warning("<TiffPage 0 @8> missing data offset")
        >>> messages
        ['missing data offset']
    """
    logger = logging.getLogger("tifffile")
    if _HELD_BACK not in logger.filters:
        logger.addFilter(_HELD_BACK)
    outer = getattr(_HELD_BACK.local, "messages", None)
    _HELD_BACK.local.messages = messages = []
    try:
        yield messages
    finally:
        _HELD_BACK.local.messages = outer
        if outer is not None:
            outer.extend(messages)


def _said(messages: list[str]) -> str:
    """``"; tifffile: ..."`` for the first few distinct messages, or ``""``."""
    distinct = list(dict.fromkeys(messages))[:3]
    return f"; tifffile: {'; '.join(distinct)}" if distinct else ""


def raster_shape(path: str | Path) -> tuple[int, ...]:
    """``(H, W)`` or ``(H, W, C)`` of a raster, read from its header only.

    Raises:
        FileFormatError: not a regular file, a header that cannot be parsed, or one that
            describes no 2-D image (fewer than two axes, or no pixels).
    """
    check_regular_file(path)
    with tifffile_log() as messages:
        try:
            shape = _header_shape(path)
        except Exception as exc:  # any decoder complaint: name the file
            raise FileFormatError(
                path, f"cannot read image header ({exc}{_said(messages)})"
            ) from exc
    if len(shape) < 2 or 0 in shape:
        raise FileFormatError(path, f"holds no 2-D image (header shape {shape}{_said(messages)})")
    return shape


def _header_shape(path: str | Path) -> tuple[int, ...]:
    """The shape a raster's header declares (any number of axes)."""
    if Path(path).suffix.lower() in TIFF_EXTS:
        import tifffile

        with tifffile.TiffFile(path) as tif:
            if not tif.series:
                return ()
            return _channels_last(tuple(int(s) for s in tif.series[0].shape))
    from PIL import Image

    with _pillow_quiet(), Image.open(path) as im:
        w, h = im.size
        bands = len(im.getbands())
    return (h, w) if bands == 1 else (h, w, bands)


def tiff_dtype(path: str | Path) -> np.dtype:
    """The sample dtype of a TIFF, read from its header only.

    Raises:
        FileFormatError: not a regular file, or a header that cannot be parsed.
    """
    check_regular_file(path)
    import tifffile

    with tifffile_log() as messages:
        try:
            with tifffile.TiffFile(path) as tif:
                return np.dtype(tif.series[0].dtype)
        except Exception as exc:  # any decoder complaint: name the file
            raise FileFormatError(
                path, f"cannot read image header ({exc}{_said(messages)})"
            ) from exc


@contextmanager
def _pillow_quiet() -> Iterator[None]:
    """Silence Pillow's decompression-bomb warning: ``max_pixels`` is the limit here
    (Pillow still refuses images over twice its own ``Image.MAX_IMAGE_PIXELS``)."""
    from PIL import Image

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        yield


def _channels_last(shape: tuple[int, ...]) -> tuple[int, ...]:
    """TIFF series shapes ``(C, H, W)`` with few planes are reported channels-last."""
    if len(shape) == 3 and shape[0] <= 4 < shape[2]:
        return (shape[1], shape[2], shape[0])
    return shape


def read_raster(path: str | Path, *, max_pixels: int = DEFAULT_MAX_PIXELS) -> np.ndarray:
    """Decode a PNG, JPEG or TIFF after checking its header size against ``max_pixels``.

    Args:
        path: the file.
        max_pixels: largest ``H * W`` accepted (checked before decoding).

    Returns:
        the samples as stored, ``(H, W)`` or ``(H, W, C)``.

    Raises:
        FileFormatError: not a regular file, too large, truncated or undecodable, or not
            2-D (a TIFF stack).
    """
    shape = raster_shape(path)
    if len(shape) not in (2, 3):
        raise FileFormatError(path, f"has {len(shape)} axes {shape}; expected one 2-D image")
    if shape[0] * shape[1] > max_pixels:
        raise FileFormatError(
            path,
            f"is {shape[1]}x{shape[0]} = {shape[0] * shape[1]:,} pixels, over the limit of "
            f"{max_pixels:,} (raise it with max_pixels)",
        )
    with tifffile_log() as messages:
        try:
            a = _decode(path)
        except Exception as exc:  # truncated or corrupt data: name the file
            raise FileFormatError(
                path, f"cannot decode the image ({exc}{_said(messages)})"
            ) from exc
    if a.shape[:2] != shape[:2]:
        raise FileFormatError(path, f"decoded to {a.shape}, but its header says {shape}")
    return a


def _decode(path: str | Path) -> np.ndarray:
    """Decode with tifffile (TIFF) or Pillow (PNG, JPEG; palette images as indices)."""
    if Path(path).suffix.lower() in TIFF_EXTS:
        import tifffile

        a = tifffile.imread(path)
        return np.moveaxis(a, 0, -1) if _channels_last(a.shape) != a.shape else a
    from PIL import Image

    with _pillow_quiet(), Image.open(path) as im:
        im.load()
        a = np.asarray(im)
    return a.astype(np.uint8) if a.dtype == bool else a
