"""Writers of tiny test files in the formats the readers accept (made by hand, not by the
code under test)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_phoenix(
    path: Path,
    magnitude: np.ndarray,
    phase: np.ndarray,
    *,
    spacing: tuple[float, float] | None = (0.2, 0.25),
    rows: int | None = None,
    target: str = "T72",
) -> Path:
    """An MSTAR Phoenix file: padded ASCII header, then big-endian float32 magnitude, phase.

    ``rows`` overrides the header's NumberOfRows (to make a header that lies)."""
    h, w = magnitude.shape
    fields = [
        ("PhoenixSigSize", "0"),
        ("NumberOfColumns", str(w)),
        ("NumberOfRows", str(rows if rows is not None else h)),
        ("TargetType", target),
    ]
    if spacing is not None:
        fields += [
            ("RangePixelSpacing", str(spacing[0])),
            ("CrossRangePixelSpacing", str(spacing[1])),
        ]

    def header(length: int) -> bytes:
        lines = ["", "[PhoenixHeaderVer01.04]", f"PhoenixHeaderLength= {length:05d}"]
        lines += [f"{k}= {v}" for k, v in fields] + ["[EndofPhoenixHeader]", ""]
        return "\n".join(lines).encode()

    length = len(header(0)) + 16
    text = header(length).ljust(length, b"\0")
    data = np.concatenate([magnitude.ravel(), phase.ravel()]).astype(">f4").tobytes()
    path.write_bytes(text + data)
    return path


def write_png(path: Path, a: np.ndarray, *, palette: bool = False) -> Path:
    """A PNG through Pillow (uint8 grey/RGB, uint16 grey; ``palette`` stores indices)."""
    from PIL import Image

    if palette:
        im = Image.frombytes("P", a.shape[::-1], a.astype(np.uint8).tobytes())
        im.putpalette([v for i in range(256) for v in (i * 7 % 256, i * 13 % 256, i * 29 % 256)])
        im.save(path)
        return path
    if a.dtype == np.uint16:
        Image.fromarray(a).save(path)
    else:
        Image.fromarray(a.astype(np.uint8)).save(path)
    return path


def write_tiff(path: Path, a: np.ndarray) -> Path:
    """A TIFF through tifffile (any dtype, complex included)."""
    import tifffile

    tifffile.imwrite(path, a)
    return path


def write_geotiff(path: Path, model_type=1, units=9001, scale=(0.75, 0.5, 0.0)) -> Path:
    """A 4x6 float TIFF with GeoTIFF ModelPixelScale (x, y, z) and a two-key GeoKeyDirectory
    (GTModelType, ProjLinearUnits; 1 = projected, 9001 = metre)."""
    import tifffile

    keys = [1, 1, 0, 2, 1024, 0, 1, model_type, 3076, 0, 1, units]
    tags = [(33550, "d", 3, scale, False), (34735, "H", len(keys), keys, False)]
    tifffile.imwrite(path, np.zeros((4, 6), np.float32), extratags=tags)
    return path


def voc_xml(filename: str, size: tuple[int, int], objects: list[tuple[str, tuple, int]]) -> str:
    """A VOC annotation: ``objects`` as ``(name, (xmin, ymin, xmax, ymax), difficult)``."""
    objs = "".join(
        f"<object><name>{n}</name><difficult>{d}</difficult><bndbox><xmin>{b[0]}</xmin>"
        f"<ymin>{b[1]}</ymin><xmax>{b[2]}</xmax><ymax>{b[3]}</ymax></bndbox></object>"
        for n, b, d in objects
    )
    return (
        f"<annotation><filename>{filename}</filename><size><width>{size[1]}</width>"
        f"<height>{size[0]}</height><depth>1</depth></size>{objs}</annotation>"
    )
