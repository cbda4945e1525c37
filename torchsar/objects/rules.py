"""Settings of the discrimination stage: one frozen, validated object shared by every detector."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from torchsar._checks import check_choice, check_int
from torchsar.errors import OptionError

__all__ = ["MAX_CLOSING", "ObjectRules"]


def _area(value: object, name: str, *, allow_none: bool) -> float | None:
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not value >= 0:
        raise OptionError(f"{name} must be a non-negative number, got {value!r}")
    if math.isinf(value) or math.isnan(value):
        raise OptionError(f"{name} must be finite, got {value!r}")
    return float(value)


MAX_CLOSING = 64
"""The largest closing radius (pixels) :class:`ObjectRules` accepts."""


@dataclass(frozen=True)
class ObjectRules:
    """How a detection mask becomes objects (the same rules for every detector of a run).

    Attributes:
        closing: radius in pixels of the morphological closing (disk) applied to the mask
            before labelling; 0 = none, at most :data:`MAX_CLOSING`. Joins fragments of
            one target (window CFARs often detect a vehicle's bright scatterers as separate
            blobs); its cost grows with the radius squared, so a radius that would join
            objects hundreds of pixels apart is refused rather than run for minutes.
        min_area: smallest object kept, in ``units``.
        max_area: largest object kept, in ``units`` (``None``: no limit). A flood of the
            whole image is then dropped rather than scored.
        units: ``"px"`` (pixels) or ``"m2"`` (square metres; needs the pixel spacing).
        connectivity: 8 (default) or 4 connected components.
        floor: objects are the components of ``score > floor`` where ``score`` is the
            normalised statistic (see :func:`~torchsar.objects.normalised_score`): 1.0 = the
            detector's design mask; a lower floor adds weaker candidates so that precision /
            FROC curves extend beyond the design operating point.

    Examples:
        >>> ObjectRules(closing=1, min_area=4).closing
        1
    """

    closing: int = 0
    min_area: float = 1.0
    max_area: float | None = None
    units: str = "px"
    connectivity: int = 8
    floor: float = 1.0

    def __post_init__(self) -> None:
        check_int(self.closing, "closing", minimum=0)
        if self.closing > MAX_CLOSING:
            raise OptionError(
                f"closing must be at most {MAX_CLOSING} px, got {self.closing} (a disk of "
                f"radius r costs about r^2 operations per pixel and joins objects 2r apart)"
            )
        lo = _area(self.min_area, "min_area", allow_none=False)
        hi = _area(self.max_area, "max_area", allow_none=True)
        if hi is not None and lo is not None and hi < lo:
            raise OptionError(f"max_area ({hi:g}) must be >= min_area ({lo:g})")
        check_choice(self.units, "units", ("px", "m2"))
        if self.connectivity not in (4, 8) or isinstance(self.connectivity, bool):
            raise OptionError(f"connectivity must be 4 or 8, got {self.connectivity!r}")
        f = self.floor
        if isinstance(f, bool) or not isinstance(f, int | float) or not 0 < f <= 1:
            raise OptionError(f"floor must be in (0, 1], got {f!r}")

    def as_dict(self) -> dict:
        """The settings as a plain dict (for ``config.json``)."""
        return asdict(self)
