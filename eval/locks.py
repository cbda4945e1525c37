"""Lock files that say whether the process that owns a folder is still alive.

A writer holds an exclusive ``flock`` on a lock file for as long as it works on what the
lock guards (a partial store, a staging folder). The kernel drops the lock when the
process dies, however it dies (SIGKILL included), so:

- the lock is held  => its owner is alive: leave its folder alone;
- the lock is free  => its owner is dead (or done): whoever takes the lock may remove
  what the dead owner left.

No host names or process ids are guessed. The lock file is removed when the holder
releases it normally; a killed holder leaves it behind, free, for the next
:func:`hold` to take over.

Caveats: ``flock`` locks are per open file, so a second :func:`hold` of the same path in
the same process is refused too, and a child made by ``fork`` shares its parent's lock
until it exits. Locks on network file systems are only as good as the server's ``flock``
support (local disks and NFSv4 are fine).

Examples:
    >>> import tempfile, pathlib
    >>> lock = pathlib.Path(tempfile.mkdtemp()) / ".job.lock"
    >>> with hold(lock):
    ...     is_held(lock)
    True
    >>> is_held(lock), lock.exists()
    (False, False)
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from torchsar_eval.errors import EvalError

__all__ = ["LockHeldError", "hold", "is_held"]

_POLL_S = 0.05


class LockHeldError(EvalError):
    """Another process holds the lock; ``path`` is the lock file."""

    def __init__(self, path: str | Path, message: str | None = None) -> None:
        self.path = str(path)
        super().__init__(message or f"{path} is held by another running process")


def _try_lock(path: Path) -> int | None:
    """An open descriptor of ``path`` holding its exclusive lock, or ``None`` if another
    process holds it. The file is created if missing; a lock taken on a file that was
    removed or replaced meanwhile (by a holder releasing it) is dropped and taken again."""
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                return None
            raise
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(path))
        except FileNotFoundError:
            same = False
        if same:
            return fd
        os.close(fd)  # the previous holder removed the file after we opened it: again


@contextmanager
def hold(path: str | Path, *, wait: float = 0.0, message: str | None = None) -> Iterator[Path]:
    """Hold the exclusive lock of ``path`` (created if missing) for the ``with`` block.

    Args:
        path: the lock file; its folder must exist.
        wait: seconds to keep trying while another process holds the lock.
        message: the :class:`LockHeldError` message when the lock stays held.

    Yields:
        ``path``. On leaving the block the file is removed, then the lock released.

    Raises:
        LockHeldError: another process still holds the lock after ``wait`` seconds.
    """
    path = Path(path)
    deadline = time.monotonic() + wait
    fd = _try_lock(path)
    while fd is None:
        if time.monotonic() >= deadline:
            raise LockHeldError(path, message)
        time.sleep(_POLL_S)
        fd = _try_lock(path)
    try:
        yield path
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)  # while held: a waiter that opened it retries on a new file
        os.close(fd)


def is_held(path: str | Path) -> bool:
    """Whether a process (this one included) holds the lock of ``path`` now; a missing
    file is not held. The file is neither created nor removed."""
    try:  # never blocks on a FIFO, never follows a planted link
        fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC | os.O_NONBLOCK | os.O_NOFOLLOW)
    except (FileNotFoundError, NotADirectoryError):
        return False
    except OSError as exc:
        if exc.errno == errno.ELOOP:  # a link is no lock of ours
            return False
        raise
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            return True
        raise
    finally:
        os.close(fd)  # closing drops a lock we took
    return False
