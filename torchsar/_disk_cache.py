"""A small on-disk cache for deterministic numerical tables (the K / G0 log-t factors).

Some design tables cost about a second to compute and are the same in every process (they
depend only on their arguments, the code that computes them and the numpy/scipy versions).
They are kept as small JSON files, one per argument tuple, so a process pays for them once
per machine instead of once per process (floats are written with ``repr``, which reads back
bit for bit).

Where: ``$TORCHSAR_CACHE`` if set (``0`` turns the cache off), else
``$XDG_CACHE_HOME/torchsar``, else ``~/.cache/torchsar``. A file that cannot be read or
written is treated as absent: the table is computed, never wrong.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np
import scipy

__all__ = ["CACHE_ENV", "cache_dir", "load", "store", "version_of"]

CACHE_ENV = "TORCHSAR_CACHE"


def cache_dir() -> Path | None:
    """The cache folder, or ``None`` when ``TORCHSAR_CACHE=0`` turns the cache off."""
    env = os.environ.get(CACHE_ENV, "")
    if env == "0":
        return None
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "torchsar"


def version_of(source: str | Path) -> str | None:
    """A version tag of a table computed by the module at ``source``: a hash of its code
    and the numpy and scipy versions (a change in any of them is a miss); ``None`` when the
    code cannot be read (then nothing is cached)."""
    try:
        digest = hashlib.sha256(Path(source).read_bytes()).hexdigest()[:16]
    except OSError:
        return None
    return f"{digest}-numpy{np.__version__}-scipy{scipy.__version__}"


def _path(table: str, key: str) -> Path | None:
    folder = cache_dir()
    if folder is None:
        return None
    return folder / table / (hashlib.sha256(key.encode()).hexdigest()[:32] + ".json")


def load(table: str, key: str) -> tuple[float, ...] | None:
    """The values stored under ``key`` in ``table``, or ``None`` (absent, unreadable, or
    written for another key)."""
    path = _path(table, key)
    if path is None:
        return None
    try:
        data = json.loads(path.read_text())
        if data.get("key") != key:
            return None
        values = tuple(float(v) for v in data["values"])
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        return None
    return values


def store(table: str, key: str, values: tuple[float, ...]) -> None:
    """Keep ``values`` under ``key`` in ``table`` (atomically; silently skipped when the
    folder cannot be written)."""
    path = _path(table, key)
    if path is None:
        return
    text = json.dumps({"key": key, "values": [float(v) for v in values]})
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    except OSError:
        return
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except OSError:
        Path(tmp).unlink(missing_ok=True)
