"""The C allocator of a process that scores shards (glibc on Linux; a no-op elsewhere).

Scoring a batch allocates and frees the same few arrays of a few MB over and over. glibc
serves such blocks with ``mmap`` and hands them back on ``free``, so every batch pays for
fresh pages again (hundreds of thousands of page faults per thousand chips, each page
zeroed by the kernel). :func:`tune_allocator` keeps blocks up to 32 MiB on the heap and the
freed heap in the process, and :func:`release_memory` hands it back once per shard, so
resident memory stays bounded by one shard's working set.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
from functools import lru_cache

__all__ = ["release_memory", "tune_allocator"]

# mallopt parameters (glibc's malloc.h)
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_MMAP_THRESHOLD = 32 << 20  # the largest glibc accepts on 64-bit systems
_TRIM_THRESHOLD = 1 << 30  # freed heap is kept until release_memory


@lru_cache(maxsize=1)
def _libc() -> ctypes.CDLL | None:
    """glibc, looked up once (``None`` without it)."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.malloc_trim, libc.mallopt  # noqa: B018 - both exist in glibc only
    except (OSError, AttributeError):
        return None
    return libc


@lru_cache(maxsize=1)
def tune_allocator() -> bool:
    """Serve the scoring's large temporary arrays from the heap instead of fresh pages
    (once per process; returns whether glibc took the settings)."""
    libc = _libc()
    if libc is None:
        return False
    return bool(libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)) and bool(
        libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD)
    )


def release_memory() -> bool:
    """Hand the memory freed by a shard back to the operating system: a collection of the
    young garbage (the shard's; a full collection would scan every object of the process,
    a tenth of a second per shard), then glibc's ``malloc_trim``. Without it the allocator
    keeps its high-water mark, so a worker's resident memory climbs over its first shards
    before it levels off. Returns whether memory was trimmed."""
    gc.collect(1)
    libc = _libc()
    return bool(libc.malloc_trim(0)) if libc is not None else False
