"""One colour per detector NAME, the same in every figure (``report.html`` and the PNG/PDF
plots), table and run: the built-in detectors have fixed, distinct colours; any other name
is hashed into the palette's other colours (never a built-in's) and gets a dashed line
style from the hash too, so two such names that share a colour still differ."""

from __future__ import annotations

import hashlib

from torchsar_eval.choices import BUILTIN_ORDER

__all__ = ["PALETTE", "detector_colour", "detector_dash"]

PALETTE = [
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
    "#393b79",
    "#637939",
    "#222222",
    "#843c39",
    "#7b4173",
    "#e7ba52",
    "#3a9e8f",
    "#a55194",
    "#6b6ecf",
    "#b35806",
]
"""Twenty colours readable on white (hex): the first 13 are the built-ins', the rest
(with ``"region-paper"``'s, the region CFAR's colour dashed) go to other names."""

_BUILTIN = BUILTIN_ORDER  # each built-in's slot, declared in its module
_SAME_AS = {"region-paper": "region"}  # the published preset of compare-region
_OTHERS = PALETTE[len(_BUILTIN) :]
_DASHES = ["--", "-.", ":"]


def _digest(name: str) -> int:
    return int.from_bytes(hashlib.blake2b(name.encode(), digest_size=8).digest(), "big")


def detector_colour(name: str) -> str:
    """The colour (``"#rrggbb"``) of detector ``name``: fixed for the built-in detectors,
    otherwise a hash of the name into :data:`PALETTE` (stable across runs and processes).

    Examples:
        >>> detector_colour("ca"), detector_colour("ca") == detector_colour("ca")
        ('#1f77b4', True)
    """
    k = _BUILTIN.get(_SAME_AS.get(name, name))
    return _OTHERS[_digest(name) % len(_OTHERS)] if k is None else PALETTE[k]


def detector_dash(name: str) -> str:
    """The line style of detector ``name`` (matplotlib's ``"-"``, ``"--"``, ``"-."``,
    ``":"``): solid for the built-in detectors, dashed for ``region-paper``, otherwise one
    of the three non-solid styles chosen by a hash of the name."""
    if name in _BUILTIN:
        return "-"
    if name in _SAME_AS:
        return "--"
    return _DASHES[(_digest(name) // len(_OTHERS)) % len(_DASHES)]
