"""Typed command-line options: comma lists and numbers checked once, at the command's edge.

Every parser raises :class:`~torchsar_eval.errors.EvalError` naming the option, what it expects and
what was given, so the CLI reports it as one line with exit status 2. Commands parse their
options here first, before any dataset is built (:func:`check_run_args` does it for ``run``).

Example:
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

import math
from argparse import Namespace
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import partial
from typing import Any, NamedTuple, TypeVar

from torch import Tensor

from torchsar.speckle import FILTERS
from torchsar_eval.detectors import (
    DETECTORS,
    DetectorSpec,
    check_options,
    dry_run,
    parse_params,
    resolve,
)
from torchsar_eval.errors import EvalError

__all__ = [
    "RunChoices",
    "at_least",
    "check_run_args",
    "despeckler",
    "floats",
    "ints",
    "names",
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


class RunChoices(NamedTuple):
    """The validated choices of ``torchsar-eval run``."""

    specs: list[DetectorSpec]
    preprocess: Callable[[Tensor], Tensor] | None
    despeckle: dict[str, Any]


def despeckler(name: str | None, items: list[str]) -> tuple[Callable | None, dict[str, Any]]:
    """The optional speckle-filter stage of ``--despeckle NAME --despeckle-param K=V`` and its
    resolved options, checked against the filter and tried once."""
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


def check_run_args(args: Namespace) -> RunChoices:
    """Validate every option of ``torchsar-eval run`` before any dataset is built."""
    at_least(args.n, "--n", 1)
    at_least(args.batch_size, "--batch-size", 1)
    wanted = ",".join(DETECTORS) if args.detectors is None else args.detectors
    chosen = names(wanted, "--detectors", DETECTORS, what="detector")
    overrides = parse_params(args.param)
    specs = resolve(chosen, overrides)
    in_metres = getattr(args, "window_units", "px") == "m"  # checked once converted
    for spec in specs:
        if spec.name in overrides and not in_metres:  # registered defaults are known to work
            dry_run(spec.fn, spec.params, f"detector {spec.name}")
    preprocess, despeckle = despeckler(args.despeckle, args.despeckle_param)
    return RunChoices(specs, preprocess, despeckle)
