"""File checks shared by the dataset and store readers.

- :func:`require_regular`: refuse a FIFO, device, socket or folder *before* opening it
  (opening a FIFO for reading blocks until someone writes to it: a hang).
- :func:`read_small`: read a small text or header file, refusing a huge one before
  reading it (a sidecar or header is bytes, not gigabytes).
- :func:`same_files`: the paths that reach one file twice (``a.png`` and ``sub/../a.png``,
  a symlink, a hard link), found by ``(st_dev, st_ino)``.
- :func:`warn_shared_files`: a warning for datasets of one run that read the same file.

Errors are :class:`~torchsar_eval.datasets.base.BadItemError` naming the file (``.path``).
"""

from __future__ import annotations

import os
import stat
import warnings
from collections.abc import Iterable, Mapping
from pathlib import Path

from torchsar_eval.errors import EvalError

__all__ = [
    "SharedFilesWarning",
    "read_small",
    "require_regular",
    "same_files",
    "warn_shared_files",
]

_KINDS = (
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISDIR, "a folder"),
)


class SharedFilesWarning(UserWarning):
    """Two datasets of one run read the same file: its items are scored in both."""


def _bad(path: str | Path, problem: str) -> EvalError:
    from torchsar_eval.datasets.base import BadItemError  # base imports this module

    return BadItemError(str(path), f"{path}: {problem}")


def require_regular(path: str | Path, what: str = "") -> os.stat_result:
    """``os.stat(path)`` of a regular file (symlinks followed); anything else refused
    without opening it.

    Args:
        path: the file.
        what: what the file is, for the message (``"store header"``).

    Raises:
        BadItemError: missing, unreadable, or not a regular file (FIFO, device, ...).
    """
    label = f" ({what})" if what else ""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise _bad(path, f"is missing{label}") from None
    except OSError as exc:
        raise _bad(path, f"cannot be read{label} ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = next((name for test, name in _KINDS if test(st.st_mode)), "not a file")
        raise _bad(path, f"is not a regular file but {kind}{label}; refused without opening it")
    return st


def read_small(path: str | Path, limit: int, what: str = "") -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes (checked before reading).

    Raises:
        BadItemError: not a regular file (see :func:`require_regular`), or larger than
            ``limit``.
    """
    size = require_regular(path, what).st_size
    if size > limit:
        label = f"{what} " if what else ""
        raise _bad(path, f"{label}is {size:,} bytes, more than the {limit:,} expected; refused")
    try:
        with open(path, "rb") as f:
            data = f.read(limit + 1)
    except OSError as exc:
        raise _bad(path, f"cannot be read ({exc.strerror})") from None
    if len(data) > limit:  # grew since the check
        raise _bad(path, f"is more than the {limit:,} bytes expected; refused")
    return data


def _identity(path: Path) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_dev, st.st_ino)


def same_files(paths: Iterable[str | Path]) -> list[tuple[Path, Path]]:
    """Pairs ``(first, again)`` of paths that reach a file already reached by an earlier
    path of ``paths`` (same device and inode: aliases through ``..``, symlinks or hard
    links); paths that cannot be stat'ed are skipped."""
    seen: dict[tuple[int, int], Path] = {}
    pairs = []
    for p in map(Path, paths):
        key = _identity(p)
        if key is None:
            continue
        if key in seen:
            pairs.append((seen[key], p))
        else:
            seen[key] = p
    return pairs


def _dataset_files(ds: object) -> list[Path]:
    """The files whose items a dataset scores: each item's image (file datasets) or the
    store header (stores)."""
    if hasattr(ds, "item_files"):  # (an annotated image that does not exist reads no file)
        return list(dict.fromkeys(f[0] for i in range(len(ds)) if (f := ds.item_files(i))))
    root = getattr(ds, "root", None)
    if root is not None and (Path(root) / "store.json").exists():
        return [Path(root) / "store.json"]
    return []


def warn_shared_files(datasets: Mapping[str, object]) -> list[tuple[str, Path, str, Path]]:
    """Warn (:class:`SharedFilesWarning`) for each pair of datasets that read a same file,
    naming both datasets and both paths; returns ``(name, path, other, other_path)`` rows.
    Datasets that overlap on purpose (a folder and one of its subfolders) are allowed:
    the warning only says that their tables count those images in both."""
    owner: dict[tuple[int, int], tuple[str, Path]] = {}
    shared: dict[tuple[str, str], list[tuple[Path, Path]]] = {}
    for name, ds in datasets.items():
        for p in _dataset_files(ds):
            key = _identity(p)
            if key is None:
                continue
            first = owner.setdefault(key, (name, p))
            if first[0] != name:
                shared.setdefault((first[0], name), []).append((first[1], p))
    rows = []
    for (a, b), pairs in shared.items():
        (pa, pb), more = pairs[0], len(pairs) - 1
        also = f" and {more} more" if more else ""
        warnings.warn(
            f"datasets {a} and {b} both read {pa} (as {pb}){also}: those images are scored "
            "in both datasets",
            SharedFilesWarning,
            stacklevel=2,
        )
        rows += [(a, x, b, y) for x, y in pairs]
    return rows
