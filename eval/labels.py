"""Short dataset labels for the console and figure titles.

A dataset is named by its full spec (``folder:/very/long/path/chips?type=display``); tables
and ``config.json`` keep that name, but the console and the figures show a short label: the
scheme, the last part of the path and the options (``folder:chips?type=display``), with
more of the path where two datasets of a run would otherwise share a label.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

__all__ = ["plain", "short_label", "short_labels"]

_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9_+-]*$")


def _split(name: str) -> tuple[str, list[str], str] | None:
    """``(scheme, path parts, options)`` of a ``scheme:path?options`` name, else ``None``."""
    scheme, colon, rest = name.partition(":")
    if not colon or not _SCHEME.match(scheme):
        return None
    path, q, query = rest.partition("?")
    parts = [p for p in re.split(r"[/\\]+", path) if p]
    return scheme, parts, q + query


def short_label(name: str, parts: int = 1) -> str:
    """``name`` with its path cut to its last ``parts`` parts.

    Examples:
        >>> short_label("folder:/very/long/path/chips?type=display")
        'folder:chips?type=display'
        >>> short_label("folder:/very/long/path/chips", parts=2)
        'folder:path/chips'
        >>> short_label("sim-chips")
        'sim-chips'
    """
    split = _split(name)
    if split is None:
        return name
    scheme, path, options = split
    if len(path) <= parts:
        return name
    return f"{scheme}:{'/'.join(path[-parts:])}{options}"


def short_labels(names: Iterable[str]) -> dict[str, str]:
    """A short label for each name, unique among them: each label gets more of its path
    until no other name shares it (the full name at worst).

    Examples:
        >>> short_labels(["folder:/a/x/chips", "folder:/b/y/chips", "coco:/d/ann.json"])
        {'folder:/a/x/chips': 'folder:x/chips', 'folder:/b/y/chips': 'folder:y/chips', \
'coco:/d/ann.json': 'coco:ann.json'}
    """
    names = list(dict.fromkeys(names))
    depth = dict.fromkeys(names, 1)
    while True:
        labels = {n: short_label(n, depth[n]) for n in names}
        shared = {n for n in names if sum(v == labels[n] for v in labels.values()) > 1}
        grow = {n for n in shared if labels[n] != n}
        if not grow:
            break
        for n in grow:
            depth[n] += 1
    return {n: labels[n] if n not in shared else n for n in names}


def plain(text: object) -> str:
    """``text`` to draw as it is in a figure: matplotlib reads ``$...$`` as mathtext (a
    detector named ``a$\\x$b`` would stop the figure), so every ``$`` is escaped.

    Examples:
        >>> print(plain("a$x$b"))
        a\\$x\\$b
    """
    return str(text).replace("$", r"\$")
