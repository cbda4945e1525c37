"""File-name parts for a run's datasets, detectors and images: short, file-safe and
unique within the run (shared by every writer of a run folder)."""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path

__all__ = ["file_slugs", "slug"]


def slug(name: str) -> str:
    """A file-name-safe form of a dataset name (``folder:../a/b`` -> ``folder_b``)."""
    if ":" in name:
        scheme, _, rest = name.partition(":")
        name = scheme + "_" + Path(rest.split("?")[0].rstrip("/")).name
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def file_slugs(names: Iterable[str], slug: Callable[[str], str]) -> dict[str, str]:
    """File-name parts for ``names`` that are unique within a run.

    ``slug(name)`` is used where it is unique; names whose slugs collide (two folders
    with the same basename) get their whole name made file-safe instead, then a counter.

    Examples:
        >>> short = lambda n: n.rsplit("/", 1)[-1]
        >>> file_slugs(["folder:a/x", "folder:b/x", "sim"], short)
        {'folder:a/x': 'folder_a_x', 'folder:b/x': 'folder_b_x', 'sim': 'sim'}
    """
    short = {n: slug(n) for n in dict.fromkeys(names)}
    uses = Counter(short.values())
    taken: set[str] = set()
    out = {}
    for n, s in short.items():
        if uses[s] > 1:
            s = re.sub(r"[^A-Za-z0-9_.-]+", "_", n)
        base, i = s, 2
        while s in taken:
            s, i = f"{base}-{i}", i + 1
        taken.add(s)
        out[n] = s
    return out
