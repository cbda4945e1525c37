"""Tiled operators: every window CFAR and speckle filter, with the reach of its footprint.

The *reach* of an operator is the largest Chebyshev distance from a pixel to a cell its
output depends on, read from the operator's own geometry:

- window CFARs (``ca``, ``go``, ``so``, ``os``, ``vi``, ``ac``, ``two_parameter``,
  ``lognormal``, ``weibull``, ``gamma``, ``k``, ``g0``): the outer box of the training ring,
  ``guard + train`` (:attr:`torchsar.windows.Ring.outer`; the pinwheel blocks of GO, SO and
  VI tile that same ring);
- speckle filters (:data:`torchsar.speckle.FILTERS`): ``window // 2`` (the Frost filters'
  per-pixel decay is computed from the same box around the same pixel, so their reach is
  one radius, not two).

The smallest image an operator accepts is ``2 * reach + 1`` on a side. AC-CFAR also has a
global statistic (its clutter mean): the runner estimates it over the whole scene first
and passes it to every tile (``clutter_mean``). The region CFAR is not a window operator
(its reach is unbounded): see :mod:`torchsar.tiling.region`.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType

import torch
from torch import Tensor

from torchsar import cfar
from torchsar._checks import check_odd
from torchsar.errors import OptionError
from torchsar.speckle import FILTERS
from torchsar.windows import Ring

__all__ = ["DETECTORS", "Operator", "operator"]

#: The window CFARs by name.
DETECTORS: dict[str, Callable[..., cfar.Detection]] = {
    name: getattr(cfar, name)
    for name in (
        "ca",
        "go",
        "so",
        "os",
        "vi",
        "ac",
        "two_parameter",
        "lognormal",
        "weibull",
        "gamma",
        "k",
        "g0",
    )
}


@dataclass(frozen=True)
class Operator:
    """A window operator ready to run on tiles.

    Attributes:
        name: the detector or filter name.
        fn: the library function, ``fn(x, **options)`` on ``(B, 1, H, W)``.
        options: its keyword options (validated names; values are checked by ``fn``).
        reach: Chebyshev reach of the footprint (pixels).
        kind: ``"detector"`` (outputs ``mask``, ``statistic``) or ``"filter"`` (``image``).
    """

    name: str
    fn: Callable[..., object]
    options: Mapping[str, object] = field(default_factory=dict)
    reach: int = 0
    kind: str = "detector"

    @property
    def min_side(self) -> int:
        """Smallest image side the operator accepts, ``2 * reach + 1``."""
        return 2 * self.reach + 1

    @property
    def outputs(self) -> tuple[str, ...]:
        """Names of the per-pixel outputs."""
        return ("mask", "statistic") if self.kind == "detector" else ("image",)

    def with_options(self, **options: object) -> Operator:
        """The same operator with more options."""
        return replace(self, options=MappingProxyType({**self.options, **options}))

    def apply(self, x: Tensor) -> dict[str, Tensor]:
        """Run on a batch ``(B, 1, H, W)``; the outputs by name, same shape."""
        out = self.fn(x, **self.options)
        if self.kind == "detector":
            return {"mask": out.mask, "statistic": out.statistic}  # type: ignore[attr-defined]
        return {"image": out}  # type: ignore[dict-item]


def _defaults(fn: Callable[..., object]) -> dict[str, object]:
    params = inspect.signature(fn).parameters
    return {k: p.default for k, p in params.items() if p.kind is inspect.Parameter.KEYWORD_ONLY}


def _check_names(name: str, fn: Callable[..., object], options: Mapping[str, object]) -> None:
    known = _defaults(fn)
    unknown = sorted(set(options) - set(known))
    if unknown:
        raise OptionError(
            f"unknown option(s) for {name}: {', '.join(unknown)} (known: {', '.join(known)})"
        )
    if "valid" in options or "clutter_mean" in options:
        raise OptionError(
            f"{name}: 'valid' and 'clutter_mean' are set by the tiled runner, not passed to it"
        )


def operator(name: str, **options: object) -> Operator:
    """The tiled operator ``name`` (a window CFAR of :data:`DETECTORS` or a speckle filter
    of :data:`torchsar.speckle.FILTERS`) with ``options``, and its reach.

    Raises:
        OptionError: unknown name or option, a bad ``guard`` / ``train`` / ``window``.

    Examples:
        >>> op = operator("ca", guard=2, train=3)
        >>> op.reach, op.min_side, op.outputs
        (5, 11, ('mask', 'statistic'))
        >>> operator("frost", window=7).reach
        3
    """
    if name in DETECTORS:
        fn, kind = DETECTORS[name], "detector"
    elif name in FILTERS:
        fn, kind = FILTERS[name], "filter"
    else:
        raise OptionError(
            f"detector must be one of {', '.join(sorted([*DETECTORS, *FILTERS, 'region']))}; "
            f"got {name!r}"
        )
    _check_names(name, fn, options)
    opts = {**_defaults(fn), **options}
    if kind == "detector":
        reach = Ring(opts["guard"], opts["train"]).outer  # type: ignore[arg-type]
    else:
        reach = check_odd(opts["window"], "window", minimum=3) // 2
    return Operator(name, fn, MappingProxyType(dict(options)), reach, kind)


def to_batch(windows: list, device: torch.device | None) -> Tensor:
    """Stack same-shape numpy windows into ``(B, 1, H, W)`` on ``device``."""
    x = torch.stack([torch.from_numpy(w) for w in windows])[:, None]
    return x if device is None else x.to(device)
