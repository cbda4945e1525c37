"""Declared sample types and the one conversion of raw samples to intensity.

Every dataset states how its samples relate to radar backscatter:

- ``intensity``: power, used as is (must be finite and non-negative).
- ``amplitude``: magnitude, squared.
- ``db``: ``10 log10`` of intensity, converted with ``10 ** (x / 10)``.
- ``complex``: complex SLC samples, ``|z| ** 2``.
- ``display``: an 8/16-bit rendering of unknown transfer (contrast stretch, log, gamma).
  Integer samples are scaled to ``[0, 1]`` by their dtype's maximum and squared as if they
  were amplitude; the result is only a monotone stand-in for intensity, so a detector's
  design Pfa does not hold on it.
"""

from __future__ import annotations

import numpy as np

from torchsar.errors import InputTypeError, InputValueError, OptionError

__all__ = ["SAMPLE_TYPES", "to_intensity"]

SAMPLE_TYPES = ("intensity", "amplitude", "db", "complex", "display")


def to_intensity(samples: np.ndarray, sample_type: str) -> np.ndarray:
    """Convert raw samples of a declared type to float32 intensity.

    Args:
        samples: array of any shape; complex for ``complex``, real otherwise.
        sample_type: one of :data:`SAMPLE_TYPES` (see the module docstring).

    Returns:
        float32 array of the same shape, non-negative intensity.

    Raises:
        OptionError: unknown ``sample_type``.
        InputTypeError: complex samples declared real, or real samples declared complex.
        InputValueError: NaN/Inf samples, or negative intensity.

    Examples:
        >>> to_intensity(np.array([0, 255], np.uint8), "display").tolist()
        [0.0, 1.0]
        >>> to_intensity(np.array([10.0, 20.0]), "db").tolist()
        [10.0, 100.0]
    """
    if sample_type not in SAMPLE_TYPES:
        raise OptionError(f"sample_type must be one of {SAMPLE_TYPES}, got {sample_type!r}")
    a = np.asarray(samples)
    if np.iscomplexobj(a) != (sample_type == "complex"):
        kind = "complex" if np.iscomplexobj(a) else "real"
        raise InputTypeError(f"samples declared {sample_type!r} must not be {kind} ({a.dtype})")
    if sample_type == "display" and a.dtype.kind in "ui":
        a = a / float(np.iinfo(a.dtype).max)
    a = a.astype(np.complex128 if sample_type == "complex" else np.float64, copy=False)
    if not np.isfinite(a).all():
        raise InputValueError(f"samples declared {sample_type!r} contain NaN or Inf")
    if sample_type == "intensity" and (a < 0).any():
        raise InputValueError(f"intensity samples must be >= 0, got minimum {a.min():g}")
    out = {
        "intensity": lambda: a,
        "amplitude": lambda: a * a,
        "display": lambda: a * a,
        "db": lambda: 10.0 ** (a / 10.0),
        "complex": lambda: a.real**2 + a.imag**2,
    }[sample_type]()
    return out.astype(np.float32)
