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

from torchsar.cfar.ac import ac, ac_threshold
from torchsar.cfar.ca import ca, ca_threshold
from torchsar.cfar.distribution import distribution_threshold
from torchsar.cfar.g0 import g0
from torchsar.cfar.gamma import gamma
from torchsar.cfar.go import go, go_threshold
from torchsar.cfar.k import k
from torchsar.cfar.lognormal import lognormal
from torchsar.cfar.os_cfar import os, os_threshold
from torchsar.cfar.so import so, so_threshold
from torchsar.cfar.two_parameter import two_parameter, two_parameter_threshold
from torchsar.cfar.vi import vi, vi_threshold
from torchsar.cfar.weibull import weibull
from torchsar.detection import Detection
from torchsar.errors import OptionError

__all__ = ["THRESHOLDS", "threshold"]

THRESHOLDS: dict[Callable[..., Detection], Callable[..., float]] = {
    ac: ac_threshold,
    ca: ca_threshold,
    g0: distribution_threshold,
    gamma: distribution_threshold,
    go: go_threshold,
    k: distribution_threshold,
    lognormal: distribution_threshold,
    os: os_threshold,
    so: so_threshold,
    two_parameter: two_parameter_threshold,
    vi: vi_threshold,
    weibull: distribution_threshold,
}
"""Each CFAR detector and the function giving its design threshold from its options."""


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
    design = THRESHOLDS[fn]
    wanted = inspect.signature(design).parameters
    return design(**{n: v for n, v in merged.items() if n in wanted})


def _resolve(detector: str | Callable[..., Detection]) -> Callable[..., Detection]:
    """The detector function for a name or function; :class:`OptionError` if unknown."""
    by_name = {fn.__name__: fn for fn in THRESHOLDS}
    fn = by_name.get(detector) if isinstance(detector, str) else detector
    if fn not in THRESHOLDS:
        raise OptionError(
            f"detector must be one of {', '.join(sorted(by_name))} (or the function); "
            f"got {detector!r}"
        )
    return fn
