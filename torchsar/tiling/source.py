"""Scene sources: anything 2-D that can be read a window at a time.

A scene is a single-channel intensity image ``(H, W)``: a torch tensor, a numpy array, a
numpy memmap, or any array-like with ``.shape``, ``.dtype`` and
``__getitem__((slice, slice)) -> numpy.ndarray`` (windowed file readers). Windows are read
lazily, one tile at a time, so the scene never needs to be in memory as float.

Complex scenes are refused: every tiled operator expects intensity (power), and which
detection of a complex image is meant (``|x|^2``, ``|x|``) is the caller's choice. Integer
scenes (quantised magnitude or power products) are read as float32; float64 scenes stay
float64 (the operators then compute in float64, as they do on a float64 tensor).
"""

from __future__ import annotations

import contextlib
import mmap
from dataclasses import dataclass

import numpy as np
import torch

from torchsar.errors import InputTypeError, InputValueError, ShapeError

__all__ = ["Scene", "as_scene"]


def _numpy_dtype(dtype: object) -> np.dtype:
    if isinstance(dtype, torch.dtype):
        if dtype.is_complex:
            return np.dtype("complex128")
        if dtype == torch.bool:
            return np.dtype("bool")
        return (
            np.dtype("float64")
            if dtype == torch.float64
            else np.dtype("float32" if dtype.is_floating_point else "int64")
        )
    return np.dtype(dtype)  # type: ignore[arg-type]


@dataclass(frozen=True)
class Scene:
    """A validated scene: its data (not copied), shape ``(H, W)`` and read dtype.

    Use :func:`as_scene` to build one; :meth:`read` returns a window as float numpy.
    """

    data: object
    shape: tuple[int, int]
    dtype: np.dtype  # float32 or float64: the dtype windows are read as
    name: str = "scene"

    def read(self, rows: slice, cols: slice) -> np.ndarray:
        """The window ``[rows, cols]`` (scene coordinates, steps of 1) as a C-contiguous
        float array of :attr:`dtype`, checked finite and non-negative.

        Raises:
            InputValueError: NaN, Inf or negative values in the window (the message names
                the scene argument and the window).
        """
        part = self.data[rows, cols]  # type: ignore[index]
        if isinstance(part, torch.Tensor):
            part = part.detach().cpu().numpy()
        arr = np.ascontiguousarray(np.asarray(part), dtype=self.dtype)
        expect = (rows.stop - rows.start, cols.stop - cols.start)
        if arr.shape != expect:
            raise ShapeError(
                f"{self.name}[{rows.start}:{rows.stop}, {cols.start}:{cols.stop}] returned shape "
                f"{arr.shape}, expected {expect}: __getitem__ must return the window asked for"
            )
        _check_window(arr, self.name, rows, cols)
        release(self.data)
        return arr


def release(data: object) -> None:
    """Unmap the pages of a shared numpy memmap touched so far (they stay in the page
    cache, and written pages are written back to the file as usual): otherwise every page
    of a scene read once, or of an output written once, counts in the process's resident
    memory until the end of the run. Anything else, and copy-on-write maps
    (``mode="c"``), are left alone."""
    mm = getattr(data, "_mmap", None)
    if isinstance(data, np.memmap) and mm is not None and getattr(data, "mode", "c") != "c":
        with contextlib.suppress(AttributeError, OSError, ValueError):  # no madvise here
            mm.madvise(mmap.MADV_DONTNEED)


def _check_window(arr: np.ndarray, name: str, rows: slice, cols: slice) -> None:
    where = f"{name}[{rows.start}:{rows.stop}, {cols.start}:{cols.stop}]"
    if arr.size == 0:
        return
    total = float(arr.sum(dtype=np.float64))
    if not np.isfinite(total) or not np.isfinite(arr).all():
        n_nan, n_inf = int(np.isnan(arr).sum()), int(np.isinf(arr).sum())
        raise InputValueError(
            f"{name} must be finite, got {n_nan} NaN and {n_inf} Inf values in {where}; "
            f"replace them (e.g. numpy.nan_to_num) before running the scene"
        )
    low = float(arr.min())
    if low < 0:
        raise InputValueError(
            f"{name} must be non-negative (SAR intensity), got minimum {low:g} in {where}"
        )


def as_scene(scene: object, name: str = "scene") -> Scene:
    """Wrap a 2-D intensity scene for tiled reading (nothing is read here).

    Args:
        scene: torch tensor, numpy array or memmap, or an array-like with ``.shape``,
            ``.dtype`` and ``__getitem__((slice, slice)) -> numpy.ndarray``; shape ``(H, W)``,
            real (float, or integer read as float32), intensity.
        name: the argument name used in error messages.

    Raises:
        InputTypeError: no ``shape`` / ``dtype`` / ``__getitem__``, a complex, bool or
            non-numeric dtype, or a tensor that requires grad.
        ShapeError: not 2-D.

    Examples:
        >>> s = as_scene(np.ones((4, 6), np.uint8))
        >>> s.shape, s.dtype, s.read(slice(1, 3), slice(0, 2)).tolist()
        ((4, 6), dtype('float32'), [[1.0, 1.0], [1.0, 1.0]])
    """
    if isinstance(scene, Scene):
        return scene
    if not all(hasattr(scene, a) for a in ("shape", "dtype", "__getitem__")):
        raise InputTypeError(
            f"{name} must be a 2-D array-like (torch tensor, numpy array or memmap, or an "
            f"object with .shape, .dtype and __getitem__((slice, slice))), got "
            f"{type(scene).__name__}"
        )
    if isinstance(scene, torch.Tensor) and scene.requires_grad:
        raise InputTypeError(f"{name} requires grad; tiled detection is not differentiable")
    shape = tuple(int(s) for s in scene.shape)  # type: ignore[attr-defined]
    if len(shape) != 2:
        raise ShapeError(f"{name} must be a 2-D (H, W) intensity scene, got shape {shape}")
    try:
        dt = _numpy_dtype(scene.dtype)  # type: ignore[attr-defined]
    except TypeError:
        raise InputTypeError(f"{name} has a non-numeric dtype {scene.dtype!r}") from None
    if dt.kind == "c":
        raise InputTypeError(
            f"{name} must be real intensity, got complex dtype {dt}; pass the intensity "
            f"(e.g. numpy.abs(x) ** 2) - tiled operators expect power, not complex samples"
        )
    if dt.kind not in "fiu":
        raise InputTypeError(f"{name} must have a real numeric dtype, got {dt}")
    read = np.dtype("float64") if dt == np.float64 else np.dtype("float32")
    return Scene(scene, (shape[0], shape[1]), read, name)
