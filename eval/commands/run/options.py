"""The command-line edge of ``torchsar-eval run``: ``--detectors``, ``--predictions`` and
``--param`` parsed into detectors, dry runs of overridden built-ins, the scoring options,
all checked before any dataset is built."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any, NamedTuple

from torch import Tensor

from torchsar.errors import TorchSARError
from torchsar.metrics import Matching
from torchsar.objects import ObjectRules
from torchsar_eval.detector import Detector
from torchsar_eval.errors import EvalError
from torchsar_eval.options import EVERY, at_least, despeckler, dry_run, parse_params
from torchsar_eval.registry import BUILTIN, load
from torchsar_eval.result import Scoring

__all__ = ["RunChoices", "check_run_args", "detector_refs", "scoring_from"]


class RunChoices(NamedTuple):
    """The validated choices of ``torchsar-eval run``."""

    detectors: list[Detector]
    preprocess: Callable[[Tensor], Tensor] | None
    despeckle: dict[str, Any]


def detector_refs(text: str) -> list[tuple[str | None, str]]:
    """``(name, reference)`` of each comma-separated ``--detectors`` item: a built-in or
    registered name, ``package.module:name``, or ``NAME=REFERENCE`` to name the row.

    Examples:
        >>> detector_refs("ca, mine=pkg.mod:Det, pkg.mod:fn")
        [(None, 'ca'), ('mine', 'pkg.mod:Det'), (None, 'pkg.mod:fn')]
    """
    items = [v.strip() for v in str(text).split(",") if v.strip()]
    if not items:
        raise EvalError(f"--detectors is empty: give at least one detector, got {text!r}")
    out = []
    for item in items:
        name, eq, ref = item.partition("=")
        if eq and not (name.strip() and ref.strip()):
            raise EvalError(f"--detectors item {item!r} must look like NAME=REFERENCE")
        out.append((name.strip(), ref.strip()) if eq else (None, item))
    return out


def _predictions(items: list[str]) -> list[tuple[str, str]]:
    out = []
    for item in items:
        name, eq, path = item.partition("=")
        if not (eq and name.strip() and path.strip()):
            raise EvalError(f"--predictions must look like NAME=FILE, got {item!r}")
        out.append((name.strip(), path.strip()))
    return out


SAVED_OPTIONS = ("threshold", "instances", "format", "iou_type", "ids")
"""The options of saved predictions."""


def _resolve(args: argparse.Namespace, overrides: dict) -> tuple[list[Detector], dict]:
    """Every detector of the run, options applied (a detector's own ``--param`` over one for
    every detector that has it), names unique; and each detector's options as applied."""
    from torchsar_eval.saved import predictions

    overrides = dict(overrides)
    every = overrides.pop(EVERY, {})
    refs = (
        []
        if args.detectors is None and args.predictions
        else (
            [(None, n) for n in BUILTIN]
            if args.detectors is None
            else detector_refs(args.detectors)
        )
    )
    names = [name or ref.rpartition(":")[2].rpartition(".")[2] for name, ref in refs]
    names += [n for n, _ in _predictions(args.predictions)]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise EvalError(
            f"--detectors / --predictions name {', '.join(twice)} more than once: "
            "name each row with NAME=..."
        )
    stray = sorted(set(overrides) - set(names))
    if stray:
        raise EvalError(f"--param given for detector(s) not being run: {stray}")
    used: set[str] = set()
    dets = []
    for (name, ref), row in zip(refs, names, strict=False):
        own = overrides.get(row, {})
        det = load(ref, name=name, options=own)
        shared = {k: v for k, v in every.items() if k not in own and det.has_option(k)}
        if shared:
            det = load(ref, name=name, options={**shared, **own})
            overrides[row] = {**shared, **own}  # (dry-run below)
            used |= shared.keys()
        dets.append(det)
    for name, path in _predictions(args.predictions):
        opts = {**{k: v for k, v in every.items() if k in SAVED_OPTIONS}, **overrides.get(name, {})}
        used |= {k for k in every if k in SAVED_OPTIONS}
        unknown = sorted(set(opts) - set(SAVED_OPTIONS))
        if unknown:
            raise EvalError(
                f"--param {name}.{unknown[0]}: saved predictions take only "
                "threshold, instances, format, iou_type and ids"
            )
        dets.append(predictions(path, name=name, **opts))
    unused = sorted(set(every) - used)
    if unused:
        raise EvalError(
            f"--param {unused[0]}=...: no detector of this run has the option {unused[0]!r}"
        )
    return dets, overrides


def parse_sweep(items: list[str]) -> dict[str, list]:
    """``--sweep KEY=V1,V2`` items as ``{KEY: [V1, V2]}`` (values as Python literals where
    they parse, else strings).

    Examples:
        >>> parse_sweep(["pfa=1e-3,1e-4", "train=4,8"])
        {'pfa': [0.001, 0.0001], 'train': [4, 8]}
    """
    import ast

    out: dict[str, list] = {}
    for item in items:
        key, eq, raw = item.partition("=")
        values = [v.strip() for v in raw.split(",")]
        if not (eq and key.strip() and all(values)):
            raise EvalError(f"--sweep must look like KEY=V1,V2,..., got {item!r}")
        if key.strip() in out:
            raise EvalError(f"--sweep gives {key.strip()} twice: list its values once")
        parsed = []
        for v in values:
            try:
                parsed.append(ast.literal_eval(v))
            except (ValueError, SyntaxError):
                parsed.append(v)
        out[key.strip()] = parsed
    return out


def check_run_args(args: argparse.Namespace) -> RunChoices:
    """Validate every option of ``torchsar-eval run`` before any dataset is built."""
    at_least(args.n, "--n", 1)
    at_least(args.batch_size, "--batch-size", 1)
    detectors, overrides = _resolve(args, parse_params(args.param))
    in_metres = getattr(args, "window_units", "px") == "m"  # checked once converted
    for det in detectors:
        if det.ref in BUILTIN and det.name in overrides and not in_metres:
            dry_run(det.fn, det.params, f"detector {det.name}")
    preprocess, despeckle = despeckler(args.despeckle, args.despeckle_param)
    return RunChoices(detectors, preprocess, despeckle)


def _matching(args: argparse.Namespace) -> Matching:
    if args.match != "distance":
        if args.max_distance is not None:
            raise EvalError("--max-distance applies to --match distance only")
        return Matching(kind=args.match, iou=args.iou, classes=_classes(args))
    if args.max_distance is None:
        raise EvalError("--match distance needs --max-distance (e.g. 200m or 20px)")
    from torchsar.metrics.distance import parse_distance

    value, units = parse_distance(args.max_distance)
    return Matching(
        kind="distance",
        max_distance=value,
        distance_units=units,
        assign=args.assign,
        classes=_classes(args),
    )


def _classes(args: argparse.Namespace) -> str:
    return "agnostic" if getattr(args, "class_agnostic", False) else "auto"


def scoring_from(args: argparse.Namespace) -> Scoring:
    """The run's :class:`Scoring` from the parsed options (validated here, before any work)."""
    if args.bootstrap < 0:
        raise EvalError(f"--bootstrap must be >= 0, got {args.bootstrap}")
    try:
        rules = ObjectRules(
            closing=args.closing,
            min_area=args.min_area,
            max_area=args.max_area,
            units=args.area_units,
            floor=args.floor,
        )
        matching = _matching(args)
    except TorchSARError as exc:
        raise EvalError(f"bad object/matching option: {exc}") from exc
    return Scoring(
        rules,
        matching,
        args.bootstrap,
        args.seed,
        instances=args.instances,
        coco_compatible=args.coco_compatible,
        bootstrap_unit=getattr(args, "bootstrap_unit", "image"),
    )
