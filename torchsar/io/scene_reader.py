"""What every scene reader does the same way: window checks, padding, intensity, closing.

A scene reader is a lazily read ``(H, W)`` raster. Its contract:

- ``shape`` -> ``(H, W)``; ``dtype`` -> the numpy dtype of the windows it returns;
- ``reader[r0:r1, c0:c1]`` -> that window as a 2-D numpy array, reading only the part of
  the file that holds it (windows reaching outside the scene raise :class:`WindowError`);
- ``read(rows, cols, fill=...)`` -> the same, padding what lies outside the scene;
- ``pixel_spacing`` -> ``(row_m, col_m)`` or ``None``; ``georef`` -> ``None`` or a mapping
  with ``pixel_to_lonlat(rows, cols)`` (see :mod:`torchsar.io.georef`);
- ``sample_type`` -> what the raw samples are (``"amplitude"``, ``"intensity"``,
  ``"complex"``... or ``None`` when the file does not say), and ``intensity`` -> whether
  windows are converted to float32 intensity (power) on the way out;
- ``close()`` and use as a context manager; readers pickle by path (a worker process that
  unpickles one reopens the file).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from torchsar.errors import OptionError
from torchsar.io.scaling import SAMPLE_TYPES, to_intensity
from torchsar.io.window import window_bounds

__all__ = ["SceneReader"]


class SceneReader(ABC):
    """Base of the scene readers: subclasses set ``shape``, ``raw_dtype``, ``georef``,
    ``pixel_spacing``, ``path`` and ``sample_type`` and implement ``_read(r0, r1, c0, c1)``
    (bounds already checked) and ``_close()``."""

    shape: tuple[int, int]
    raw_dtype: np.dtype
    path: str
    georef: Any = None
    pixel_spacing: tuple[float, float] | None = None
    sample_type: str | None = None
    intensity: bool = False

    def _set_intensity(self, as_intensity: bool, sample_type: str | None) -> None:
        """Validate the intensity options against what the file holds."""
        if sample_type is not None:
            if sample_type not in SAMPLE_TYPES:
                raise OptionError(
                    f"sample_type must be one of {SAMPLE_TYPES} or None, got {sample_type!r}"
                )
            if (sample_type == "complex") != (self.raw_dtype.kind == "c"):
                raise OptionError(
                    f"sample_type={sample_type!r} does not fit {self.path}'s "
                    f"{self.raw_dtype} samples"
                )
            self.sample_type = sample_type
        if as_intensity and self.sample_type is None:
            raise OptionError(
                f"as_intensity=True, but {self.path} does not say whether its "
                f"{self.raw_dtype} samples are amplitude or intensity; pass sample_type "
                "('amplitude', 'intensity', 'db' or 'display')"
            )
        self.intensity = bool(as_intensity)

    @property
    def dtype(self) -> np.dtype:
        """dtype of the windows returned: float32 with ``as_intensity``, else as stored."""
        return np.dtype(np.float32) if self.intensity else self.raw_dtype

    def __getitem__(self, window: object) -> np.ndarray:
        r0, r1, c0, c1 = window_bounds(window, self.shape)
        return self._out(self._read(r0, r1, c0, c1))

    def read(self, rows: tuple[int, int], cols: tuple[int, int], *, fill: float = 0) -> np.ndarray:
        """The window ``rows[0]:rows[1], cols[0]:cols[1]``, padded with ``fill`` where it
        lies outside the scene (the bounds may be negative or past the edge).

        Raises:
            WindowError: ``rows`` or ``cols`` not increasing integer pairs.
        """
        (r0, r1), (c0, c1) = _pair(rows, "rows"), _pair(cols, "cols")
        h, w = self.shape
        out = np.full((r1 - r0, c1 - c0), fill, dtype=self.dtype)
        ir0, ir1, ic0, ic1 = max(r0, 0), min(r1, h), max(c0, 0), min(c1, w)
        if ir0 < ir1 and ic0 < ic1:
            out[ir0 - r0 : ir1 - r0, ic0 - c0 : ic1 - c0] = self[ir0:ir1, ic0:ic1]
        return out

    def _out(self, a: np.ndarray) -> np.ndarray:
        return to_intensity(a, self.sample_type) if self.intensity else a

    @abstractmethod
    def _read(self, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        """The window ``[r0:r1, c0:c1]`` as stored (bounds already checked)."""

    @abstractmethod
    def _close(self) -> None:
        """Release the file (called once per :meth:`close`; must be idempotent)."""

    def close(self) -> None:
        """Release the file (idempotent)."""
        self._close()

    def __enter__(self) -> SceneReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        h, w = self.shape
        kind = "intensity float32" if self.intensity else str(self.raw_dtype)
        return f"<{type(self).__name__} {self.path!r} {h}x{w} {kind}>"


def _pair(v: object, name: str) -> tuple[int, int]:
    from torchsar.io.window import WindowError

    try:
        lo, hi = (int(x) for x in v)  # type: ignore[union-attr]
        ok = all(float(x) == int(x) for x in v)  # type: ignore[union-attr]
    except (TypeError, ValueError) as exc:
        raise WindowError(f"{name} must be a (start, stop) pair of integers, got {v!r}") from exc
    if not ok or hi < lo:
        raise WindowError(f"{name} must be a (start, stop) pair with start <= stop, got {v!r}")
    return lo, hi
