"""Design thresholds without an image: what ``detector(x, **options).threshold`` would be.

Every CFAR's threshold depends on its options only (window, ``pfa`` and the variant's own
parameters), never on the image, so it can be asked for directly, e.g. to sweep a
statistic computed once against the thresholds of many ``pfa`` values. Each variant module
owns its ``<name>_threshold`` function, which the detector itself uses for its
:class:`~torchsar.detection.Detection`; :func:`threshold` looks it up by detector.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

from torchsar.catalog import builtin_specs
from torchsar.detection import Detection
from torchsar.errors import OptionError

__all__ = ["threshold"]  # and THRESHOLDS, built on first use (see __getattr__)


def __getattr__(name: str) -> Any:
    if name == "THRESHOLDS":  # built on first use: the modules declare them
        return _thresholds()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _thresholds() -> dict[Callable[..., Detection], Callable[..., float]]:
    """Each CFAR detector and the function giving its design threshold from its options
    (``THRESHOLDS``; from the detectors' own declarations, :mod:`torchsar.catalog`)."""
    return {s.detect: s.threshold for s in builtin_specs() if s.threshold is not None}


def threshold(detector: str | Callable[..., Detection], **options: Any) -> float:
    """The design threshold ``detector(x, **options).threshold`` for any image ``x``.

    Args:
        detector: a CFAR detector of :mod:`torchsar.cfar` or its name (``"ca"``, ``"os"``, ...).
        **options: the detector's keyword options (``guard``, ``train``, ``pfa``, ...);
            omitted ones take the detector's defaults, ``valid`` is ignored.

    Returns:
        The threshold as a float.

    Raises:
        OptionError: unknown detector, an option the detector does not have, or an invalid
            option value (as the detector itself would raise).

    Examples:
        >>> from torchsar.cfar.thresholds import ca_factor
        >>> threshold("ca", guard=1, train=2, pfa=1e-3) == ca_factor(40, 1e-3)
        True
    """
    fn = _resolve(detector)
    params = inspect.signature(fn).parameters
    unknown = sorted(set(options) - set(params) | ({"x"} & set(options)))
    if unknown:
        allowed = ", ".join(p for p in params if p not in ("x", "valid"))
        raise OptionError(f"{fn.__name__} has no option {', '.join(unknown)}; options: {allowed}")
    merged = {n: p.default for n, p in params.items() if p.default is not inspect.Parameter.empty}
    merged.update(options)
    design = _thresholds()[fn]
    wanted = inspect.signature(design).parameters
    return design(**{n: v for n, v in merged.items() if n in wanted})


def _resolve(detector: str | Callable[..., Detection]) -> Callable[..., Detection]:
    """The detector function for a name or function; :class:`OptionError` if unknown."""
    by_name = {fn.__name__: fn for fn in _thresholds()}
    fn = by_name.get(detector) if isinstance(detector, str) else detector
    if fn not in _thresholds():
        raise OptionError(
            f"detector must be one of {', '.join(sorted(by_name))} (or the function); "
            f"got {detector!r}"
        )
    return fn
