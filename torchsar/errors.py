"""Every error type torchsar raises, in one public place.

All are subclasses of :class:`TorchSARError` and of the built-in type a caller would
catch (``TypeError``, ``ValueError``, ``IndexError``, ``RuntimeError``), so code that
catches those keeps working. Messages name the argument, what was expected and what was
given.

- :class:`InputTypeError` (``TypeError``): not a tensor, integer where float is expected,
  complex where real is expected (or the reverse).
- :class:`ShapeError` (``ValueError``): wrong number of dimensions or mismatched shapes.
- :class:`InputValueError` (``ValueError``): NaN, Inf or negative values.
- :class:`WindowSizeError` (``ValueError``): a window that does not fit in the image;
  :class:`WindowError` (also ``IndexError``): a scene window that is not two slices inside
  the scene.
- :class:`OptionError` (``ValueError``): an invalid keyword option (out of range, unknown
  mode).
- :class:`FileFormatError` (``ValueError``): a file that is missing, unreadable, too large
  or not the format it claims (``path`` and ``problem`` as attributes).
- :class:`GeorefError` (``ValueError``): a georeferencing that cannot give what was asked.
- :class:`UnsettledError` (``RuntimeError``): a region CFAR tile whose regions still reach
  a cut side at the largest halo.

Examples:
    >>> import torch
    >>> from torchsar.cfar import ca
    >>> try:
    ...     ca(torch.full((1, 1, 16, 16), float("nan")))
    ... except InputValueError as exc:
    ...     print(type(exc).__name__, isinstance(exc, ValueError))
    InputValueError True
"""

from __future__ import annotations

from pathlib import Path

__all__ = [
    "FileFormatError",
    "GeorefError",
    "InputTypeError",
    "InputValueError",
    "OptionError",
    "ShapeError",
    "TorchSARError",
    "UnsettledError",
    "WindowError",
    "WindowSizeError",
]


class TorchSARError(Exception):
    """Base class of every error torchsar raises for bad input."""


class InputTypeError(TorchSARError, TypeError):
    """An argument has the wrong type or dtype (e.g. complex where real is expected)."""


class ShapeError(TorchSARError, ValueError):
    """An argument has the wrong number of dimensions or a mismatched shape."""


class InputValueError(TorchSARError, ValueError):
    """An argument holds invalid values (NaN, Inf, negative intensity)."""


class WindowSizeError(TorchSARError, ValueError):
    """A window (guard + training band, filter window) is larger than the image."""


class WindowError(WindowSizeError, IndexError):
    """A window that is not two unit-step slices inside the scene."""


class OptionError(TorchSARError, ValueError):
    """A keyword option is out of range or not one of the allowed values."""


class FileFormatError(TorchSARError, ValueError):
    """A file is missing, unreadable, too large or not the format it claims.

    Attributes:
        path: the offending file (``str``), so callers can skip and count it.
        problem: what is wrong with it, without the path.
    """

    def __init__(self, path: str | Path, problem: str) -> None:
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


class GeorefError(TorchSARError, ValueError):
    """A mapping cannot give what was asked (lon/lat of a projected CRS without pyproj),
    or pixel coordinates that are not finite real numbers."""


class UnsettledError(TorchSARError, RuntimeError):
    """A region CFAR tile whose regions still reach a cut side of its window at
    ``max_halo``."""
