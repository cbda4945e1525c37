"""Input validation used by every public function.

One place decides what a valid input is, so every entry point raises the same typed errors
(:mod:`torchsar.errors`) with messages that name the argument, what was expected and what
was given.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np
import torch
from torch import Tensor

from torchsar.errors import (
    InputTypeError,
    InputValueError,
    OptionError,
    ShapeError,
    WindowSizeError,
)

__all__ = [
    "all_finite",
    "check_choice",
    "check_complex",
    "check_device",
    "check_ids",
    "check_image",
    "check_int",
    "check_mask",
    "check_odd",
    "check_pairs",
    "check_per_plane",
    "check_positive",
    "check_probability",
    "check_range",
    "check_real",
    "check_same_shape",
    "check_window_fits",
    "float_dtype",
    "has_nan",
]


_AXES = {2: "(H, W)", 3: "(C, H, W)", 4: "(B, C, H, W)"}


def float_dtype(dtype: torch.dtype) -> torch.dtype:
    """Return the floating dtype computations use for an input dtype.

    float64 stays float64 (and complex128 maps to float64); every other dtype computes in
    float32. This is the single dtype policy of the library.
    """
    return torch.float64 if dtype in (torch.float64, torch.complex128) else torch.float32


def _summable(x: Tensor) -> Tensor:
    """``x``, or its complex64 copy for complex32 (half-precision complex), which torch
    cannot sum or compare on every device."""
    return x.to(torch.complex64) if x.dtype == torch.complex32 else x


def all_finite(x: Tensor) -> bool:
    """Whether every value of ``x`` is finite. One summation decides the usual case (a sum
    is finite only if every term is); an overflowing sum falls back to the elementwise
    test."""
    x = _summable(x)
    return bool(torch.isfinite(x.sum())) or bool(torch.isfinite(x).all())


def has_nan(x: Tensor) -> bool:
    """Whether ``x`` holds a NaN. One summation decides the usual case (a NaN makes the sum
    NaN); a NaN sum (e.g. ``inf - inf``) falls back to the elementwise test."""
    x = _summable(x)
    return bool(torch.isnan(x.sum())) and bool(torch.isnan(x).any())


def check_image(
    x: object,
    name: str = "x",
    *,
    ndim: int = 4,
    complex_ok: bool = False,
    real_ok: bool = True,
    nonnegative: bool = True,
    not_differentiable: str | None = None,
    values: bool = True,
) -> Tensor:
    """Validate an image batch and return it unchanged.

    Autograd policy (the library's one rule): functions whose output is a decision (CFAR
    detectors, region growing) are not differentiable and pass their own name as
    ``not_differentiable``, so an input that requires grad is refused with the fix in the
    message, instead of failing deep inside or returning gradients that ignore the decision.

    Args:
        x: the candidate tensor.
        name: the argument name used in error messages.
        ndim: required number of dimensions (4 for ``(B, C, H, W)``).
        complex_ok: accept complex dtypes.
        real_ok: accept real floating dtypes.
        nonnegative: require every value >= 0 (intensity/amplitude). Ignored for complex.
        not_differentiable: the calling function's name if it does not support autograd:
            then ``x.requires_grad`` is an error.
        values: check the values (finite, and non-negative where asked); ``False`` leaves
            them to the caller, a kernel that reads every value anyway and then calls this
            again to raise the error.

    Returns:
        ``x`` itself (no copy).

    Raises:
        InputTypeError: not a tensor, integer/bool dtype, complex/real where not allowed, or
            requires grad where ``not_differentiable`` is given.
        ShapeError: wrong number of dimensions.
        InputValueError: NaN, Inf, or negative values where forbidden.

    Examples:
        >>> check_image(torch.ones(2, 1, 8, 8)).shape
        torch.Size([2, 1, 8, 8])
    """
    if not isinstance(x, Tensor):
        raise InputTypeError(f"{name} must be a torch.Tensor, got {type(x).__name__}")
    if x.dim() != ndim:
        axes = _AXES.get(ndim, f"{ndim} dims")
        raise ShapeError(
            f"{name} must have shape {axes} ({ndim} dims), got {tuple(x.shape)} ({x.dim()} dims)"
        )
    is_complex = x.is_complex()
    if is_complex and not complex_ok:
        raise InputTypeError(
            f"{name} must be real (intensity or amplitude), got complex dtype {x.dtype}; "
            f"pass x.abs().square() for intensity"
        )
    if not is_complex and not real_ok:
        raise InputTypeError(f"{name} must be complex, got real dtype {x.dtype}")
    if not is_complex and not x.is_floating_point():
        raise InputTypeError(
            f"{name} must have a floating dtype, got {x.dtype}; use {name}.float()"
        )
    if not_differentiable is not None and x.requires_grad:
        raise InputTypeError(
            f"{name} requires grad; {not_differentiable} is not differentiable: "
            f"pass {name}.detach()"
        )
    if x.numel() == 0 or not values:
        return x
    low = None
    if nonnegative and not is_complex:  # one pass: NaN propagates to both, Inf to one
        low, high = torch.stack(torch.aminmax(_summable(x).reshape(-1))).tolist()
    finite = all_finite(x) if low is None else math.isfinite(low) and math.isfinite(high)
    if not finite:
        n_nan = int(torch.isnan(_summable(x)).sum())
        n_inf = int(torch.isinf(_summable(x)).sum())
        raise InputValueError(
            f"{name} must be finite, got {n_nan} NaN and {n_inf} Inf values; "
            f"replace them (e.g. {name}.nan_to_num(0.0, 0.0, 0.0)); where they mark no-data, "
            f"also pass a detector's `valid` mask ({name}.isfinite()) so those cells count nowhere"
        )
    if low is not None and low < 0:
        raise InputValueError(
            f"{name} must be non-negative (SAR intensity/amplitude), got minimum {low:g}"
        )
    return x


def check_complex(x: object, name: str = "x", *, ndim: int = 3) -> Tensor:
    """Validate a complex tensor (phase history or SLC image) of ``ndim`` dimensions."""
    return check_image(x, name, ndim=ndim, complex_ok=True, real_ok=False)


def check_mask(mask: object, like: Tensor, name: str = "valid") -> Tensor:
    """Validate a boolean mask broadcastable to ``like``; return it as a bool tensor."""
    if not isinstance(mask, Tensor):
        raise InputTypeError(f"{name} must be a torch.Tensor, got {type(mask).__name__}")
    if mask.dtype != torch.bool:
        raise InputTypeError(f"{name} must be a bool tensor, got dtype {mask.dtype}")
    if not broadcasts(mask.shape, like.shape):
        raise ShapeError(f"{name} must broadcast to {tuple(like.shape)}, got {tuple(mask.shape)}")
    return mask.to(like.device)


def broadcasts(a: tuple[int, ...], b: tuple[int, ...]) -> bool:
    """Whether shapes ``a`` and ``b`` broadcast together (numpy's rule, the same as torch's;
    ``torch.broadcast_shapes`` imports sympy on its first call, half a second)."""
    try:
        np.broadcast_shapes(tuple(a), tuple(b))
    except ValueError:
        return False
    return True


def check_same_shape(a: Tensor, b: Tensor, name_a: str, name_b: str) -> None:
    """Raise :class:`ShapeError` unless ``a`` and ``b`` have the same shape."""
    if a.shape != b.shape:
        raise ShapeError(
            f"{name_a} and {name_b} must have the same shape, "
            f"got {tuple(a.shape)} and {tuple(b.shape)}"
        )


def check_int(value: object, name: str, *, minimum: int | None = None) -> int:
    """Validate an integer option (bools rejected) with an optional lower bound."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise OptionError(f"{name} must be an int, got {value!r}")
    if minimum is not None and value < minimum:
        raise OptionError(f"{name} must be >= {minimum}, got {value}")
    return value


def check_odd(value: object, name: str, *, minimum: int = 1) -> int:
    """Validate an odd integer window size >= ``minimum``."""
    v = check_int(value, name, minimum=minimum)
    if v % 2 == 0:
        raise OptionError(f"{name} must be odd, got {v}")
    return v


def check_positive(value: object, name: str, *, allow_zero: bool = False) -> float:
    """Validate a finite real number > 0 (or >= 0 with ``allow_zero``)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise OptionError(f"{name} must be a real number, got {value!r}")
    v = float(value)
    ok = v >= 0 if allow_zero else v > 0
    if not ok or v != v or v in (float("inf"), float("-inf")):
        bound = ">= 0" if allow_zero else "> 0"
        raise OptionError(f"{name} must be finite and {bound}, got {value!r}")
    return v


def check_probability(value: object, name: str = "pfa") -> float:
    """Validate a probability strictly between 0 and 1."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0 < value < 1:
        raise OptionError(f"{name} must be a probability in (0, 1), got {value!r}")
    return float(value)


def check_choice(value: object, name: str, choices: Iterable[str]) -> str:
    """Validate a string mode against its allowed values (listed in the error)."""
    allowed: Sequence[str] = tuple(choices)
    if value not in allowed:
        raise OptionError(f"{name} must be one of {', '.join(map(repr, allowed))}; got {value!r}")
    return value  # type: ignore[return-value]


def check_window_fits(x: Tensor, extent: int | tuple[int, int], name: str = "window") -> None:
    """Raise :class:`WindowSizeError` if a window of ``extent`` pixels exceeds the image.

    Args:
        x: image batch ``(..., H, W)``.
        extent: full window size (e.g. ``2 * (guard + train) + 1``), or ``(height, width)``.
        name: how the window is described in the message (e.g. ``"guard + train"``).
    """
    eh, ew = (extent, extent) if isinstance(extent, int) else extent
    h, w = x.shape[-2], x.shape[-1]
    if eh > h or ew > w:
        raise WindowSizeError(
            f"{name} window of {eh}x{ew} pixels is larger than the image ({h}x{w}); "
            f"use a smaller window or a larger image"
        )


def check_range(
    value: object, name: str, *, minimum: float | None = None, maximum: float | None = None
) -> tuple[float, float]:
    """Validate a ``(low, high)`` pair of finite reals with ``low <= high`` inside the bounds."""
    ok = isinstance(value, tuple | list) and len(value) == 2
    ok = ok and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
    if ok:
        low, high = float(value[0]), float(value[1])
        ok = low <= high and all(v == v and abs(v) != float("inf") for v in (low, high))
        ok = ok and (minimum is None or low >= minimum) and (maximum is None or high <= maximum)
    if not ok:
        bounds = (
            f" within [{minimum}, {maximum}]" if minimum is not None or maximum is not None else ""
        )
        raise OptionError(
            f"{name} must be a pair (low, high) of reals, low <= high{bounds}; got {value!r}"
        )
    return low, high


def check_device(device: object, name: str = "device") -> torch.device | None:
    """``device`` as a :class:`torch.device` (``None`` kept), refused when it is unavailable.

    Raises:
        OptionError: not a device, or a CUDA/MPS device on a machine without one.

    Examples:
        >>> check_device("cpu")
        device(type='cpu')
    """
    if device is None:
        return None
    try:
        dev = torch.device(device)  # type: ignore[arg-type]
    except (RuntimeError, TypeError):
        raise OptionError(
            f"{name} must be a torch device (a torch.device or a name such as 'cpu'), "
            f"got {device!r}"
        ) from None
    if dev.type == "meta":
        raise OptionError(f"{name} = {device!r} holds no data (shapes only): use cpu or cuda")
    available = {
        "cuda": torch.cuda.is_available,
        "mps": lambda: torch.backends.mps.is_available(),
    }.get(dev.type, lambda: True)
    if not available():
        raise OptionError(
            f"{name} = {device!r} is not available on this machine (no {dev.type} device); "
            f"use {name}='cpu'"
        )
    return dev


def check_pairs(x: object, name: str, *, ndim: int, axes: str) -> Tensor:
    """Validate a real floating tensor of ``ndim`` dims whose last axis holds 2 coordinates.

    ``axes`` describes the expected layout in messages, e.g. ``"(B, N, 2) (range, azimuth)"``.
    NaN is allowed (a missing measurement).

    Examples:
        >>> check_pairs(torch.zeros(1, 3, 2), "positions", ndim=3, axes="(B, N, 2)").shape
        torch.Size([1, 3, 2])
    """
    if not isinstance(x, Tensor) or not x.is_floating_point():
        raise InputTypeError(f"{name} must be a real floating tensor, got {x!r:.60}")
    if x.dim() != ndim or x.shape[-1] != 2:
        raise ShapeError(f"{name} must have shape {axes}, got {tuple(x.shape)}")
    return x


def check_real(value: object, name: str) -> Tensor:
    """Validate a real number or a real tensor / array that may hold ``±inf`` but no NaN
    (e.g. a detection threshold); return it as a tensor (a Python number as float64).

    Raises:
        InputTypeError: not a real number, or a complex, bool or non-numeric array.
        InputValueError: a NaN value.

    Examples:
        >>> check_real(2.0, "threshold")
        tensor(2., dtype=torch.float64)
    """
    numeric = int | float | np.number | np.ndarray | Tensor | list | tuple
    if isinstance(value, bool) or not isinstance(value, numeric):
        raise InputTypeError(f"{name} must be a real number or tensor, got {value!r:.60}")
    try:
        t = torch.as_tensor(value, dtype=torch.float64 if isinstance(value, int | float) else None)
    except (TypeError, ValueError, RuntimeError):
        raise InputTypeError(f"{name} must be a real number or tensor, got {value!r:.60}") from None
    if t.is_complex() or t.dtype == torch.bool:
        raise InputTypeError(f"{name} must be real, got dtype {t.dtype}")
    if t.is_floating_point() and t.numel() and has_nan(t):
        n = int(torch.isnan(t).sum())
        raise InputValueError(f"{name} must not be NaN, got {n} NaN value(s)")
    return t


def check_per_plane(value: object, name: str, planes: int) -> np.ndarray:
    """Validate a finite number > 0, or one such value per image plane; return a float64
    ``(planes,)`` array (a single value is used for every plane).

    Raises:
        InputTypeError: not real numbers.
        ShapeError: neither one value nor ``planes`` values.
        InputValueError: a NaN, infinite or non-positive value.

    Examples:
        >>> check_per_plane(0.25, "pixel_area", 3).tolist()
        [0.25, 0.25, 0.25]
    """
    if isinstance(value, Tensor):
        value = value.detach().cpu().numpy()
    arr = np.asarray(value)
    if arr.dtype == bool or not (
        np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)
    ):
        raise InputTypeError(f"{name} must be a real number or one per plane, got {value!r:.60}")
    arr = arr.astype(np.float64).reshape(-1)
    if arr.size not in (1, planes):
        raise ShapeError(
            f"{name} must be one value or one per plane ({planes}), got {arr.size} values"
        )
    ok = np.isfinite(arr) & (arr > 0)
    if not ok.all():
        raise InputValueError(f"{name} must be finite and > 0, got {float(arr[~ok][0]):g}")
    return np.broadcast_to(arr, (planes,)).copy()


def check_ids(value: object, name: str, *, ndim: int = 3) -> np.ndarray:
    """Validate instance / label ids (0 = none, positive ids) of ``ndim`` dimensions and
    return them as an int64 array.

    Integer and bool dtypes are accepted as they are; floating ids are accepted when every
    value is a whole number (e.g. a label map read from a float image), else refused.

    Raises:
        InputTypeError: not numeric (complex, strings, objects), or floating ids that are
            not whole numbers (or NaN / Inf).
        ShapeError: wrong number of dimensions.
        InputValueError: a negative id.

    Examples:
        >>> check_ids(np.array([[[0.0, 2.0]]]), "instances").dtype
        dtype('int64')
    """
    if isinstance(value, Tensor):
        value = value.detach().cpu().numpy()
    arr = np.asarray(value)
    kind = arr.dtype.kind
    if kind not in "biuf":
        raise InputTypeError(f"{name} must hold integer ids, got dtype {arr.dtype}")
    if arr.ndim != ndim:
        axes = {3: "(N, H, W)", 2: "(H, W)"}.get(ndim, f"{ndim} dims")
        raise ShapeError(f"{name} must have shape {axes} ({ndim} dims), got {arr.shape}")
    if kind == "f":
        whole = np.isfinite(arr) & (arr == np.floor(arr))
        if not whole.all():
            bad = float(arr[~whole].reshape(-1)[0])
            raise InputTypeError(
                f"{name} must hold whole-number ids, got {bad:g} (dtype {arr.dtype}); "
                f"ids are integers: 0 = none, 1, 2, ... per instance"
            )
    if kind != "b" and arr.size and arr.min() < 0:
        raise InputValueError(f"{name} must hold non-negative ids (0 = none), got {int(arr.min())}")
    return arr.astype(np.int64, copy=False)
