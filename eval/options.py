"""Typed command-line options: comma lists and numbers checked once, at the command's edge.

Every parser raises :class:`~torchsar_eval.errors.EvalError` naming the option, what it expects and
what was given, so the CLI reports it as one line with exit status 2. Commands parse their
options here first, before any dataset is built (:func:`check_run_args` does it for ``run``).

Examples:
    >>> ints("3,5, 7", "--windows", minimum=3)
    [3, 5, 7]
    >>> floats("1e-3,1e-4", "--pfa", above=0, below=1)
    [0.001, 0.0001]
    >>> names("ca, go", "--detectors", ["ca", "go", "so"])
    ['ca', 'go']
    >>> ints("0", "--n", minimum=1)
    Traceback (most recent call last):
    ...
    torchsar_eval.errors.EvalError: --n must be >= 1, got 0
"""

from __future__ import annotations

import ast
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from functools import partial
from typing import Any, TypeVar

from torchsar_eval.errors import EvalError

__all__ = [
    "at_least",
    "despeckler",
    "dry_run",
    "floats",
    "ints",
    "names",
    "parse_params",
]

Number = TypeVar("Number", int, float)


def _items(text: str, option: str) -> list[str]:
    items = [v.strip() for v in str(text).split(",") if v.strip()]
    if not items:
        raise EvalError(f"{option} is empty: give at least one value, got {text!r}")
    return items


def _convert(text: str, option: str, kind: Callable[[str], Number], what: str) -> list[Number]:
    items = _items(text, option)
    try:
        return [kind(v) for v in items]
    except ValueError:
        raise EvalError(f"{option} must be comma-separated {what}, got {text!r}") from None


@dataclass(frozen=True)
class _Range:
    """Strict (``above``, ``below``) and inclusive (``minimum``, ``maximum``) bounds."""

    above: float | None = None
    below: float | None = None
    minimum: float | None = None
    maximum: float | None = None

    def __contains__(self, v: float) -> bool:
        return math.isfinite(v) and all(
            b is None or test(v, b) for b, test in zip(self._bounds(), _TESTS.values(), strict=True)
        )

    def _bounds(self) -> tuple[float | None, ...]:
        return (self.above, self.below, self.minimum, self.maximum)

    def __str__(self) -> str:
        parts = [
            f"{op} {b:g}" for op, b in zip(_TESTS, self._bounds(), strict=True) if b is not None
        ]
        return " and ".join(parts) or "finite"


_TESTS = {
    ">": lambda v, b: v > b,
    "<": lambda v, b: v < b,
    ">=": lambda v, b: v >= b,
    "<=": lambda v, b: v <= b,
}


def _checked(values: list[Number], text: str, option: str, limits: _Range) -> list[Number]:
    bad = [v for v in values if v not in limits]
    if bad:
        if len(values) == 1:
            raise EvalError(f"{option} must be {limits}, got {bad[0]:g}")
        raise EvalError(f"{option} values must be {limits}, got {text.strip()!r}")
    return values


def ints(
    text: str, option: str, *, minimum: int | None = None, maximum: int | None = None
) -> list[int]:
    """A comma list of integers within ``[minimum, maximum]`` (each optional)."""
    values = _convert(text, option, int, "integers")
    return _checked(values, text, option, _Range(minimum=minimum, maximum=maximum))


def floats(
    text: str,
    option: str,
    *,
    above: float | None = None,
    below: float | None = None,
    minimum: float | None = None,
    maximum: float | None = None,
) -> list[float]:
    """A comma list of finite numbers; ``above``/``below`` are strict bounds,
    ``minimum``/``maximum`` inclusive ones (each optional)."""
    values = _convert(text, option, float, "numbers")
    return _checked(values, text, option, _Range(above, below, minimum, maximum))


def names(text: str, option: str, allowed: Iterable[str], *, what: str = "name") -> list[str]:
    """A comma list of distinct names, each one of ``allowed`` (``what`` names the kind)."""
    valid = list(allowed)
    items = _items(text, option)
    unknown = [v for v in items if v not in valid]
    if unknown:
        raise EvalError(f"{option}: unknown {what} {unknown[0]!r}; valid: {', '.join(valid)}")
    twice = sorted({v for v in items if items.count(v) > 1})
    if twice:
        raise EvalError(f"{option} lists {', '.join(twice)} more than once")
    return items


def at_least(value: Number | None, option: str, minimum: Number) -> Number | None:
    """``value`` itself if it is ``None`` or ``>= minimum``; an :class:`EvalError` otherwise."""
    if value is not None and value not in _Range(minimum=minimum):
        raise EvalError(f"{option} must be >= {minimum}, got {value}")
    return value


MAX_PARAM = 1000
"""Longest ``DETECTOR.NAME=VALUE`` accepted (no option needs more; refused before parsing)."""


EVERY = "*"
"""The detector name of an option for every detector that has it (``*.pfa=1e-6`` or
``pfa=1e-6``)."""


def parse_params(items: list[str], option: str = "--param") -> dict[str, dict[str, Any]]:
    """Parse ``["ca.guard=3", "region.k=0.5"]`` into ``{"ca": {"guard": 3}, ...}`` (values
    as Python literals where they parse, else strings); ``NAME=VALUE`` or ``*.NAME=VALUE``
    go under :data:`EVERY` (every detector that has the option).

    Examples:
        >>> parse_params(["ca.guard=3", "mine.mode=fast", "pfa=1e-6", "*.train=8"])
        {'ca': {'guard': 3}, 'mine': {'mode': 'fast'}, '*': {'pfa': 1e-06, 'train': 8}}
    """
    out: dict[str, dict[str, Any]] = {}
    for item in items:
        if len(item) > MAX_PARAM:
            raise EvalError(
                f"{option} {item[:40]}...: {len(item)} characters, more than the "
                f"{MAX_PARAM} an option value may have"
            )
        key, eq, raw = item.partition("=")
        name, dot, param = key.partition(".") if "." in key else (EVERY, ".", key)
        if not (eq and dot and name and param) or "." in param:
            raise EvalError(
                f"{option} must look like DETECTOR.NAME=VALUE (or NAME=VALUE for "
                f"every detector that has the option), got {item!r}"
            )
        try:
            value = ast.literal_eval(raw)
        except (ValueError, SyntaxError, RecursionError, MemoryError):
            value = raw  # a bare string such as a mode name
        out.setdefault(name, {})[param] = value
    return out


DRY_SIDE = 257
"""Largest side of the image of :func:`dry_run` (a larger window is checked by the run)."""


def dry_run(fn: Callable, options: Mapping[str, Any], what: str) -> None:
    """Call ``fn(image, **options)`` once on a small clutter image, so a bad option value
    (out of range, wrong type, a threshold that cannot be computed) fails before any
    work, as an :class:`EvalError` naming ``what`` and the options."""
    # the library only when an option is tried: the command parsers import this module
    from torchsar.simulate import clutter

    try:
        reach = 2 * (int(options.get("guard") or 0) + int(options.get("train") or 0))
        side = max(32, reach + int(options.get("window") or 0) + 1)
    except (TypeError, ValueError):
        side = 32  # a malformed window option: the call names it
    if side > DRY_SIDE:
        return
    try:
        fn(clutter((1, 1, side, side), seed=0), **options)
    except Exception as exc:  # whatever the library raises for these options
        shown = ", ".join(f"{k}={v!r}" for k, v in options.items())
        raise EvalError(f"{what} rejects its options ({shown}): {exc}") from exc


def despeckler(name: str | None, items: list[str]) -> tuple[Callable | None, dict[str, Any]]:
    """The optional speckle-filter stage of ``--despeckle NAME --despeckle-param K=V`` and its
    resolved options, checked against the filter and tried once."""
    # the library only when a filter is named: the command parsers import this module
    from torchsar.speckle import FILTERS
    from torchsar_eval.detector import check_options

    if name is None:
        if items:
            raise EvalError("--despeckle-param given without --despeckle")
        return None, {}
    bad = [item for item in items if "=" not in item or item.startswith("=")]
    if bad:
        raise EvalError(f"--despeckle-param must look like KEY=VALUE, got {bad[0]!r}")
    opts = parse_params([f"{name}.{item}" for item in items]).get(name, {})
    what = f"speckle filter {name}"
    check_options(FILTERS[name], opts, what)
    dry_run(FILTERS[name], opts, what)
    return partial(FILTERS[name], **opts), opts
