"""Open a whole SAR scene for windowed reading, choosing the reader by file content.

TIFF family (TIFF, BigTIFF, GeoTIFF, COG, Sentinel-1 measurement files) ->
:class:`~torchsar.io.tiff_scene.TiffScene`; NITF (SICD) ->
:class:`~torchsar.io.sicd.SicdScene` (needs the optional ``sarpy``). The readers share
one contract, described in :mod:`torchsar.io.scene_reader`.
"""

from __future__ import annotations

from pathlib import Path

from torchsar.io.errors import FileFormatError
from torchsar.io.raster import check_regular_file
from torchsar.io.scene_reader import SceneReader

__all__ = ["open_scene"]

_TIFF_MAGIC = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")


def open_scene(
    path: str | Path,
    *,
    band: int | None = None,
    sample_type: str | None = None,
    as_intensity: bool = False,
) -> SceneReader:
    """A lazily read scene: ``scene[r0:r1, c0:c1]`` reads only that window from disk.

    Args:
        path: a TIFF-family file or a SICD NITF.
        band: sample (or full-resolution page) of a multi-band TIFF; ``None`` for one band.
        sample_type: what the samples are, when the file does not say (one of
            ``torchsar.io.SAMPLE_TYPES``). Complex data are ``"complex"`` and Sentinel-1 GRD
            files ``"amplitude"`` without being told.
        as_intensity: windows come back as float32 intensity (power): amplitude squared,
            ``|z|**2`` of complex samples, ``10**(x/10)`` of dB. Otherwise raw samples.

    Returns:
        a :class:`~torchsar.io.scene_reader.SceneReader` (close it, or use ``with``).

    Raises:
        FileFormatError: missing, empty, not a supported format, truncated or corrupt.
        OptionError: a band the file lacks; ``as_intensity`` without a known sample type.
        ImportError: a SICD file without sarpy installed.

    Examples:
        >>> import tempfile, numpy as np, tifffile
        >>> path = tempfile.mkdtemp() + "/grd.tif"
        >>> amp = np.full((300, 200), 3, np.uint16)
        >>> tifffile.imwrite(path, amp, tile=(64, 64), compression="zlib")
        >>> with open_scene(path, sample_type="amplitude", as_intensity=True) as scene:
        ...     scene.shape, scene.dtype, float(scene[0:2, 0:2].max())
        ((300, 200), dtype('float32'), 9.0)
    """
    check_regular_file(path)
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError as exc:  # /proc/self/mem and the like: a "regular" file that reads no bytes
        raise FileFormatError(path, f"cannot be read ({exc.strerror or exc})") from None
    if len(head) < 4:
        raise FileFormatError(path, f"is {len(head)} bytes long: not a scene file")
    if head in _TIFF_MAGIC:
        from torchsar.io.tiff_scene import TiffScene

        return TiffScene(path, band=band, sample_type=sample_type, as_intensity=as_intensity)
    if head == b"NITF":
        from torchsar.io.sicd import SicdScene

        if band not in (None, 0):
            from torchsar.errors import OptionError

            raise OptionError(f"band must be None for a SICD product, got {band!r}")
        return SicdScene(path, sample_type=sample_type, as_intensity=as_intensity)
    raise FileFormatError(path, f"is neither a TIFF nor a NITF/SICD file (starts with {head!r})")
