"""Options of the region-growing CFAR: the paper's preset, ours, and their validation.

Every option of :func:`~torchsar.region.region_cfar` lives in one frozen dataclass,
:class:`RegionParams`; :class:`RegionOptions` types the same options as keyword arguments.
A *preset* gives the defaults; the keyword arguments given override them. ``"paper"`` is the
seed paper read literally (section 3, steps a–j, section 4 values); ``"torchsar"`` keeps the
paper's growth and ring geometry and adds the fixes for the failure modes measured on
simulated speckle (see :mod:`torchsar.region.detector`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from typing import TypedDict, Unpack

from torch import Tensor

from torchsar._checks import check_choice, check_int, check_odd, check_positive
from torchsar.errors import OptionError
from torchsar.region.grow import DEFAULT_BUDGET
from torchsar.speckle import FILTERS

__all__ = ["PRESETS", "RegionOptions", "RegionParams", "resolve_params"]

Despeckle = str | Callable[[Tensor], Tensor] | None


@dataclass(frozen=True)
class RegionParams:
    """All options of the region-growing CFAR (see :func:`region_cfar` for their meaning)."""

    tau: float = 0.3
    floor: float = 0.0
    n_init: int = 4
    guard: int = 3
    background: int = 3
    k: float = 0.25
    min_background: int = 15
    despeckle: Despeckle = "enhanced_frost"
    seed_window: int = 5
    connectivity: int = 4
    target_on: str = "raw"
    lowpass: str | int | None = "despeckled"
    blocking: str = "all"
    max_size: int | None = None
    max_fraction: float | None = None
    min_size: int = 1
    merge: int | None = None
    fill_holes: bool = False
    budget: int | None = DEFAULT_BUDGET
    workers: int = 1


class RegionOptions(TypedDict, total=False):
    """The keyword options of :func:`~torchsar.region.region_cfar`, typed (each optional:
    an option not given comes from the preset). Same names and types as
    :class:`RegionParams`."""

    tau: float
    floor: float
    n_init: int
    guard: int
    background: int
    k: float
    min_background: int
    despeckle: Despeckle
    seed_window: int
    connectivity: int
    target_on: str
    lowpass: str | int | None
    blocking: str
    max_size: int | None
    max_fraction: float | None
    min_size: int
    merge: int | None
    fill_holes: bool
    budget: int | None
    workers: int


PRESETS: dict[str, RegionParams] = {
    "paper": RegionParams(),
    "torchsar": RegionParams(
        tau=0.5,
        floor=0.02,
        k=2.0,
        max_size=20_000,
        max_fraction=0.25,
        min_size=30,
        merge=0,
        fill_holes=True,
    ),
}


def _check_despeckle(value: Despeckle) -> Despeckle:
    if isinstance(value, str):
        if value not in FILTERS:
            raise OptionError(
                f"despeckle={value!r} is not a filter of torchsar.speckle (one of "
                f"{', '.join(sorted(FILTERS))}); pass a filter name, a callable or None"
            )
        return value
    if value is None or callable(value):
        return value
    raise OptionError(
        f"despeckle must be a filter name (e.g. 'enhanced_frost'), a callable or None, "
        f"got {value!r}"
    )


def _check_lowpass(value: str | int | None) -> str | int | None:
    if value is None or value == "despeckled":
        return value
    if isinstance(value, int) and not isinstance(value, bool):
        return check_odd(value, "lowpass")
    raise OptionError(f"lowpass must be 'despeckled', None or an odd box width, got {value!r}")


def _check_fraction(value: object, inside: Callable[[float], bool], message: str) -> float:
    """``value`` as a float if it is a real number that ``inside`` accepts, else ``message``."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not inside(value):
        raise OptionError(f"{message}, got {value!r}")
    return float(value)


def _check_bool(value: object, name: str) -> bool:
    if not isinstance(value, bool):
        raise OptionError(f"{name} must be True or False, got {value!r}")
    return value


def _validate(p: RegionParams) -> RegionParams:
    max_size = None if p.max_size is None else check_int(p.max_size, "max_size", minimum=1)
    merge = None if p.merge is None else check_int(p.merge, "merge", minimum=0)
    max_fraction = (
        None
        if p.max_fraction is None
        else _check_fraction(
            p.max_fraction, lambda v: 0 < v <= 1, "max_fraction must be None or in (0, 1]"
        )
    )
    conn = check_int(p.connectivity, "connectivity")
    if conn not in (4, 8):
        raise OptionError(f"connectivity must be 4 or 8, got {conn}")
    return RegionParams(
        tau=check_positive(p.tau, "tau"),
        floor=_check_fraction(
            p.floor, lambda v: 0 <= v < 1, "floor must be in [0, 1) (a fraction of the seed's F)"
        ),
        n_init=check_int(p.n_init, "n_init", minimum=1),
        guard=check_int(p.guard, "guard", minimum=0),
        background=check_int(p.background, "background", minimum=1),
        k=check_positive(p.k, "k", allow_zero=True),
        min_background=check_int(p.min_background, "min_background", minimum=1),
        despeckle=_check_despeckle(p.despeckle),
        seed_window=check_odd(p.seed_window, "seed_window"),
        connectivity=conn,
        target_on=check_choice(p.target_on, "target_on", ("raw", "despeckled")),
        lowpass=_check_lowpass(p.lowpass),
        blocking=check_choice(p.blocking, "blocking", ("all", "targets")),
        max_size=max_size,
        max_fraction=max_fraction,
        min_size=check_int(p.min_size, "min_size", minimum=1),
        merge=merge,
        fill_holes=_check_bool(p.fill_holes, "fill_holes"),
        budget=None if p.budget is None else check_int(p.budget, "budget", minimum=1),
        workers=check_int(p.workers, "workers", minimum=1),
    )


def resolve_params(preset: str, **overrides: Unpack[RegionOptions]) -> RegionParams:
    """The preset's options with every non-``None`` override applied, validated.

    Callers pass only the keywords the user gave, so ``None`` is a real value here (e.g.
    ``max_size=None`` means no size limit).

    Raises:
        OptionError: unknown preset or an invalid option.
    """
    check_choice(preset, "preset", tuple(PRESETS))
    names = {f.name for f in fields(RegionParams)}
    unknown = set(overrides) - names
    if unknown:
        raise OptionError(f"unknown region_cfar option(s): {', '.join(sorted(unknown))}")
    return _validate(replace(PRESETS[preset], **overrides))
