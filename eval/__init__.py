"""torchsar's evaluation harness: score any detector, or saved predictions, against
ground truth at dataset scale.

The public API (imported lazily, so the command line starts fast):

- :func:`evaluate`: datasets x detectors -> :class:`Results` (tables as DataFrames; a run
  folder with ``out=``).
- :class:`Evaluator`: the same scoring batch by batch from a training loop
  (``update(predictions, targets)``, ``compute()``, ``+``, ``state_dict()``); typed
  dataset items :class:`Item`, :class:`Targets`, :class:`ImageMeta`.
- :class:`Detector`, :func:`load` (built-in names, entry points, ``module:name`` import
  paths), :func:`predictions` (saved COCO results, point CSV, mask folders).
- :class:`Scoring`, :class:`Execution`, :class:`Calibration`; :class:`EvalError`.
- Re-exported from torchsar for convenience: ``Objects`` (what a detector may return
  besides a ``Detection``), ``ObjectRules``, ``Matching``.
"""

from __future__ import annotations

import importlib

__all__ = [
    "BUILTIN",
    "Calibration",
    "Detector",
    "EvalError",
    "Evaluator",
    "Execution",
    "ImageMeta",
    "Item",
    "Matching",
    "ObjectRules",
    "Objects",
    "Results",
    "Scoring",
    "Targets",
    "evaluate",
    "load",
    "predictions",
]

_HOMES = {
    "BUILTIN": "torchsar_eval.registry",
    "Calibration": "torchsar_eval.settings",
    "Detector": "torchsar_eval.detector",
    "EvalError": "torchsar_eval.errors",
    "Evaluator": "torchsar_eval.result",
    "Execution": "torchsar_eval.settings",
    "ImageMeta": "torchsar_eval.items",
    "Item": "torchsar_eval.items",
    "Matching": "torchsar.metrics",
    "ObjectRules": "torchsar.objects",
    "Objects": "torchsar.objects",
    "Results": "torchsar_eval.api",
    "Scoring": "torchsar_eval.result",
    "Targets": "torchsar_eval.items",
    "evaluate": "torchsar_eval.api",
    "load": "torchsar_eval.registry",
    "predictions": "torchsar_eval.saved",
}


def __getattr__(name: str) -> object:
    if name not in _HOMES:
        raise AttributeError(f"module 'torchsar_eval' has no attribute {name!r}")
    return getattr(importlib.import_module(_HOMES[name]), name)


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
