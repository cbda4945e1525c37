"""Lock files that say whether the process that made a folder still works on it.

A writer holds an exclusive ``flock`` on a lock file for as long as it works; the kernel
drops the lock when the process ends, however it ends (exit, crash, ``kill -9``), so a lock
file that nobody holds belongs to a dead writer. Unlike host names and process ids in file
names, this survives a renamed host, a reused process id and a folder shared between
machines (on file systems with working ``flock``, which includes local disks and NFS v4).

Example:
    >>> import tempfile, pathlib
    >>> lock = pathlib.Path(tempfile.mkdtemp()) / "work.lock"
    >>> with hold(lock):
    ...     is_held(lock)
    True
    >>> is_held(lock), lock.exists()
    (False, False)
"""

from __future__ import annotations

import errno
import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["hold", "is_held"]


@contextmanager
def hold(path: Path) -> Iterator[Path]:
    """Create ``path`` and hold an exclusive lock on it until the block ends; the file is
    removed on the way out. Raises :class:`BlockingIOError` when another process holds it."""
    path = Path(path)
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            if _same_file(fd, path):
                break
        except OSError:
            os.close(fd)
            raise
        os.close(fd)  # someone removed the file between our open and our lock: again
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        yield path
    finally:
        path.unlink(missing_ok=True)
        os.close(fd)  # releases the lock


def _same_file(fd: int, path: Path) -> bool:
    try:
        st = os.stat(path, follow_symlinks=False)
    except FileNotFoundError:
        return False
    own = os.fstat(fd)
    return (st.st_dev, st.st_ino) == (own.st_dev, own.st_ino)


def is_held(path: Path) -> bool:
    """Whether a live process holds the lock file ``path`` (``False`` when it is absent)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError as exc:
        return exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES)
    finally:
        os.close(fd)
    return False
