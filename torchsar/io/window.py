"""Window arguments of scene readers: two slices inside the image, checked in one place."""

from __future__ import annotations

from torchsar.errors import WindowError

__all__ = ["WindowError", "window_bounds"]


def window_bounds(window: object, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """``(r0, r1, c0, c1)`` of ``(slice(r0, r1), slice(c0, c1))`` inside an ``(H, W)`` scene.

    ``None`` bounds mean the image edge; empty windows (``r0 == r1``) are valid. Negative
    bounds are refused rather than counted from the end, and so are windows reaching past
    the edge: a scene reader never clips silently (``read(..., fill=)`` pads instead).

    Raises:
        WindowError: not two slices, a step other than 1, or bounds outside the scene.

    Examples:
        >>> window_bounds((slice(0, 10), slice(None)), (100, 50))
        (0, 10, 0, 50)
    """
    if not (isinstance(window, tuple) and len(window) == 2):
        raise WindowError(f"window must be (slice(r0, r1), slice(c0, c1)), got {window!r}")
    out = []
    for name, s, n in zip(("rows", "cols"), window, shape, strict=True):
        if not isinstance(s, slice) or s.step not in (None, 1):
            raise WindowError(f"window {name} must be a slice with step 1, got {s!r}")
        lo = 0 if s.start is None else s.start
        hi = n if s.stop is None else s.stop
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in (lo, hi)):
            try:
                lo, hi = _index(lo), _index(hi)
            except TypeError as exc:
                raise WindowError(f"window {name} bounds must be integers, got {s!r}") from exc
        if not 0 <= lo <= hi <= n:
            raise WindowError(
                f"window {name} {lo}:{hi} is outside the scene's 0:{n} {name} (shape "
                f"{shape[0]}x{shape[1]}); use read(..., fill=) to pad outside"
            )
        out += [lo, hi]
    return out[0], out[1], out[2], out[3]


def _index(v: object) -> int:
    """An integer-like bound (numpy integers) as int; TypeError otherwise."""
    import operator

    return operator.index(v)
