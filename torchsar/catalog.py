"""The built-in detectors, read from their own modules: each declares itself once as a
module-level ``SPEC`` (:class:`~torchsar.detection.DetectorSpec`) in :mod:`torchsar.cfar`
or :mod:`torchsar.region`, and every registry (the evaluator's built-in names, the CFAR
design thresholds, the command line's choices, the report's colours) is built from them.

Adding a built-in CFAR is one new module in ``torchsar/cfar/`` ending with its ``SPEC``,
plus its export in ``torchsar/cfar/__init__.py``.
"""

from __future__ import annotations

import importlib
import pkgutil
from functools import cache

from torchsar.detection import DetectorSpec

__all__ = ["PACKAGES", "builtin_specs"]

PACKAGES = ("torchsar.cfar", "torchsar.region")
"""The packages whose modules may declare a built-in detector."""


@cache
def builtin_specs() -> tuple[DetectorSpec, ...]:
    """Every built-in detector's declaration, in its ``order`` (the default run's).

    Examples:
        >>> [s.name for s in builtin_specs()][:3]
        ['ca', 'two_parameter', 'go']

    Raises:
        RuntimeError: two declarations share a name or an order (a broken tree).
    """
    found: list[DetectorSpec] = []
    for package in PACKAGES:
        pkg = importlib.import_module(package)
        for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
            module = importlib.import_module(f"{package}.{info.name}")
            spec = getattr(module, "SPEC", None)
            if isinstance(spec, DetectorSpec):
                found.append(spec)
    for key in ("name", "order"):
        values = [getattr(s, key) for s in found]
        if len(set(values)) != len(values):
            raise RuntimeError(f"two built-in detectors declare the same {key}: {values}")
    return tuple(sorted(found, key=lambda s: s.order))
