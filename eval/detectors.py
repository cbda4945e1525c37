"""The detector registry: a detector is one function plus one line here.

Each :class:`DetectorSpec` names a function ``fn(x, **params) -> Detection`` and its default
parameters; the CLI overrides them with ``--param NAME.KEY=VALUE``.
"""

from __future__ import annotations

import ast
import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from torch import Tensor

import torchsar as ts
from torchsar.cfar import Detection
from torchsar.simulate import clutter
from torchsar_eval.errors import EvalError

__all__ = ["DETECTORS", "DetectorSpec", "check_options", "dry_run", "parse_params", "resolve"]


@dataclass(frozen=True)
class DetectorSpec:
    """A registered detector: ``fn(x, **params)`` with default ``params``."""

    name: str
    fn: Callable[..., Detection]
    params: Mapping[str, Any] = field(default_factory=dict)

    def with_params(self, overrides: Mapping[str, Any]) -> DetectorSpec:
        return DetectorSpec(self.name, self.fn, {**self.params, **overrides})

    def __call__(self, x: Tensor) -> Detection:
        return self.fn(x, **self.params)


WINDOW = {"guard": 2, "train": 4, "pfa": 1e-3}
LOOKS = {**WINDOW, "looks": 1.0}

DETECTORS: dict[str, DetectorSpec] = {
    s.name: s
    for s in [
        DetectorSpec("ca", ts.cfar.ca, WINDOW),
        DetectorSpec("two_parameter", ts.cfar.two_parameter, WINDOW),
        DetectorSpec("go", ts.cfar.go, WINDOW),
        DetectorSpec("so", ts.cfar.so, WINDOW),
        DetectorSpec("os", ts.cfar.os, {**WINDOW, "rank": None}),
        DetectorSpec("vi", ts.cfar.vi, {**WINDOW, "k_vi": 4.76, "k_mr": 1.806}),
        DetectorSpec("ac", ts.cfar.ac, {**WINDOW, "censor_pfa": None, "iterations": 3}),
        DetectorSpec("lognormal", ts.cfar.lognormal, WINDOW),
        DetectorSpec("weibull", ts.cfar.weibull, WINDOW),
        DetectorSpec("gamma", ts.cfar.gamma, LOOKS),
        DetectorSpec("k", ts.cfar.k, LOOKS),
        DetectorSpec("g0", ts.cfar.g0, LOOKS),
        DetectorSpec("region", ts.region.region_cfar, {}),
    ]
}


def parse_params(items: list[str]) -> dict[str, dict[str, Any]]:
    """Parse ``["ca.guard=3", "region.k=0.5"]`` into ``{"ca": {"guard": 3}, ...}``."""
    out: dict[str, dict[str, Any]] = {}
    for item in items:
        key, eq, raw = item.partition("=")
        name, dot, param = key.partition(".")
        if not (eq and dot and name and param):
            raise EvalError(f"--param must look like DETECTOR.NAME=VALUE, got {item!r}")
        try:
            value = ast.literal_eval(raw)
        except (ValueError, SyntaxError):
            value = raw  # a bare string such as a mode name
        out.setdefault(name, {})[param] = value
    return out


def check_options(fn: Callable, options: Mapping[str, Any], what: str) -> None:
    """Every key of ``options`` must be a keyword option of ``fn`` (unless it takes
    ``**options``, which the function checks itself)."""
    params = list(inspect.signature(fn).parameters.values())[1:]  # after the image
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        return
    valid = [p.name for p in params if p.kind is not inspect.Parameter.POSITIONAL_ONLY]
    unknown = [k for k in options if k not in valid]
    if unknown:
        raise EvalError(f"{what} has no option {unknown[0]!r}; valid: {', '.join(valid)}")


DRY_SIDE = 257
"""Largest side of the image of :func:`dry_run` (a larger window is checked by the run)."""


def dry_run(fn: Callable, options: Mapping[str, Any], what: str) -> None:
    """Call ``fn(image, **options)`` once on a small clutter image, so a bad option value
    (out of range, wrong type, a threshold that cannot be computed) fails before any
    work, as an :class:`EvalError` naming ``what`` and the options."""
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


def resolve(names: list[str], params: Mapping[str, Mapping[str, Any]]) -> list[DetectorSpec]:
    """Look detectors up by name and apply parameter overrides (all checked first)."""
    unknown = [n for n in list(names) + list(params) if n not in DETECTORS]
    if unknown:
        raise EvalError(f"unknown detector {unknown[0]!r}; valid: {', '.join(sorted(DETECTORS))}")
    stray = set(params) - set(names)
    if stray:
        raise EvalError(f"--param given for detector(s) not being run: {sorted(stray)}")
    for n, over in params.items():
        check_options(DETECTORS[n].fn, over, f"detector {n}")
    return [DETECTORS[n].with_params(params.get(n, {})) for n in names]
