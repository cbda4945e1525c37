"""Detectors by name: the built-in CFARs, installed packages' entry points and import paths.

A reference names a detector in one of three ways, tried in this order:

- a built-in name (:data:`BUILTIN`: ``ca``, ``os``, ``region``, ...);
- an entry-point name: an installed package registers ``name = "module:attribute"`` in
  the entry-point group ``torchsar.detectors`` (``[project.entry-points."torchsar.detectors"]``
  in its ``pyproject.toml``);
- an import path ``package.module:attribute`` (the attribute may be dotted).

The target of an entry point or import path is a :class:`~torchsar_eval.detector.Detector`,
a detector callable ``fn(images, **options)`` (a function or an object with ``__call__``),
or a *factory*: a class, or a callable without a required positional argument, that is
called once with the options and returns the detector (e.g. a class that loads a CNN's
weights in ``__init__``). The detector remembers the reference, so worker processes and
Ray tasks rebuild it by importing it rather than receiving a pickled function.
"""

from __future__ import annotations

import importlib
import inspect
import os
import sys
from collections.abc import Mapping
from dataclasses import replace
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from torchsar.catalog import builtin_specs
from torchsar_eval.detector import Detector, as_detector, split_options, use_loader
from torchsar_eval.errors import EvalError

__all__ = ["BUILTIN", "ENTRY_POINT_GROUP", "available", "load", "registered"]

ENTRY_POINT_GROUP = "torchsar.detectors"

BUILTIN: dict[str, Detector] = {
    s.name: Detector(s.name, s.detect, dict(s.options), ref=s.name) for s in builtin_specs()
}
"""The built-in detectors with their default options (the ``run`` command's default set)."""


def registered() -> dict[str, EntryPoint]:
    """Detectors that installed packages register in the ``torchsar.detectors`` group."""
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def available() -> list[str]:
    """Every detector name: built-ins, then registered entry points (sorted)."""
    return [*BUILTIN, *sorted(set(registered()) - set(BUILTIN))]


def _import(path: str) -> object:
    """The object of ``module:attribute``; the working directory is searched too (a module
    beside the user, as ``python -m`` would find it; worker processes inherit the path)."""
    module, _, attr = path.partition(":")
    if not module or not attr:
        raise EvalError(f"detector {path!r}: an import path looks like package.module:name")
    if "" not in sys.path and os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())
    try:
        obj: object = importlib.import_module(module)
    except (Exception, SystemExit) as exc:  # ImportError, or raised while importing
        raise EvalError(f"cannot import detector {path!r}: {type(exc).__name__}: {exc}") from None
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise EvalError(
                f"cannot import detector {path!r}: module {module!r} has no attribute {attr!r}"
            ) from None
    return obj


def _is_factory(obj: object) -> bool:
    """A class, or a callable whose parameters all have defaults (it cannot take images)."""
    if isinstance(obj, type):
        return True
    try:
        params = inspect.signature(obj).parameters.values()  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False
    positional = (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    return not any(p.kind in positional and p.default is p.empty for p in params) and not any(
        p.kind is inspect.Parameter.VAR_POSITIONAL for p in params
    )


def _target(ref: str) -> tuple[object, str]:
    """The object a non-built-in reference points to, and its default row name."""
    eps = registered()
    if ref in eps:
        try:
            return eps[ref].load(), ref
        except Exception as exc:
            raise EvalError(
                f"cannot load registered detector {ref!r} ({eps[ref].value}): "
                f"{type(exc).__name__}: {exc}"
            ) from None
    if ":" not in ref:
        raise EvalError(
            f"unknown detector {ref!r}; valid: {', '.join(available())}, or an "
            "import path package.module:name"
        )
    return _import(ref), ref.rpartition(":")[2].rpartition(".")[2]


def load(
    ref: str,
    *,
    name: str | None = None,
    options: Mapping[str, Any] | None = None,
    threshold: float | None = None,
    instances: str = "auto",
    scale: str = "auto",
) -> Detector:
    """The detector a reference names (see the module docstring), with ``options``
    overriding its defaults and the harness settings ``threshold`` / ``instances`` /
    ``scale``.

    Examples:
        >>> d = load("ca", options={"guard": 3})
        >>> d.name, d.options["guard"], d.options["train"]
        ('ca', 3, 4)
    """
    options = dict(options or {})
    if ref in BUILTIN:
        det = BUILTIN[ref].with_options(options)
        kept = _settings(det, threshold, instances, scale)
        return replace(det, name=name or ref, **kept)
    obj, default = _target(ref)
    if isinstance(obj, Detector):
        base = obj.with_options(options)
        default = obj.name
    elif _is_factory(obj):
        passed, harness = split_options(obj, options)
        try:
            built = obj(**passed)  # type: ignore[operator]
        except TypeError as exc:
            raise EvalError(f"detector {ref!r} rejects its options {passed}: {exc}") from None
        except (Exception, SystemExit) as exc:  # its own __init__ failed: one line naming it
            raise EvalError(
                f"detector {ref!r} could not be built: {type(exc).__name__}: {exc}"
            ) from None
        base = replace(as_detector(built), options=passed, call_options={}, **harness)
    else:
        base = as_detector(obj).with_options(options)
    kept = _settings(base, threshold, instances, scale)
    return replace(base, name=name or default, ref=ref, **kept)


def _settings(
    det: Detector, threshold: float | None, instances: str, scale: str = "auto"
) -> dict[str, Any]:
    """The harness settings: explicit arguments over the detector's own."""
    return {
        "threshold": det.threshold if threshold is None else threshold,
        "instances": det.instances if instances == "auto" else instances,
        "scale": det.scale if scale == "auto" else scale,
    }


use_loader(load)  # detectors rebuilt from their reference (options, worker processes) use it
