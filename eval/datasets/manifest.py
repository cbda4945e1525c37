"""Dataset manifest: which files, how many bytes, and one hash that ties a table to them."""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable
from pathlib import Path

__all__ = ["file_manifest"]


def file_manifest(root: str | Path, files: Iterable[str | Path]) -> dict:
    """File count, total bytes and a sha256 of the sorted ``relative-path<TAB>size`` list,
    and one of the list with each file's modification time too.

    The hashes cover names, sizes and times, not contents (reading every byte of a large
    dataset would cost a full pass); symlinks that resolve outside ``root`` are listed.

    Returns:
        ``{"root", "files", "bytes", "sha256", "sha256_mtime", "symlinks_outside"}``.
    """
    root = Path(root)
    base = root if root.is_dir() else root.parent
    inside = base.resolve()
    rows, timed, outside, total = [], [], [], 0
    for f in sorted({Path(p) for p in files}):
        st = os.stat(f)
        total += st.st_size
        rel = os.path.relpath(f, base)
        rows.append(f"{rel}\t{st.st_size}\n")
        timed.append(f"{rel}\t{st.st_size}\t{st.st_mtime_ns}\n")
        if f.is_symlink() and not f.resolve().is_relative_to(inside):
            outside.append(rel)
    digest = hashlib.sha256("".join(rows).encode()).hexdigest()
    return {
        "root": str(root),
        "files": len(rows),
        "bytes": total,
        "sha256": digest,
        "sha256_mtime": hashlib.sha256("".join(timed).encode()).hexdigest(),
        "symlinks_outside": outside,
    }
