"""Run folders: published whole or not at all, never mixed with an older run.

A command writes its results into a hidden *staging* folder beside ``--out`` and publishes
it with one rename (:func:`result_dir`), so ``--out`` holds either nothing or a complete
run. :func:`claim` checks ``--out`` before any work and, with ``--overwrite``, moves the
previous run aside until the new one is published (then deletes it; on failure it is put
back). Hidden folders left by a killed run are recognised by their names (a marker word,
the host and the dead process id) and settled on the next start (:func:`recover`):
staging folders are deleted, a previous run moved aside is deleted if a new run replaced
it and put back otherwise.
"""

from __future__ import annotations

import errno
import json
import os
import platform
import re
import secrets
import shutil
import socket
import sys
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

import torchsar
from torchsar_eval.errors import EvalError

__all__ = [
    "HOST",
    "Hidden",
    "check_out",
    "claim",
    "default_out",
    "file_slugs",
    "hidden_folders",
    "recover",
    "result_dir",
    "write_config",
]

RUN_MARKER = "config.json"
"""Every published run folder holds this file; only such folders are ever replaced."""

HOST = re.sub(r"[^A-Za-z0-9.-]+", "_", socket.gethostname()) or "host"
"""This host's name as written in the names of hidden folders."""
_HIDDEN = re.compile(
    r"^\.(?P<name>.+)\.torchsar-(?P<kind>partial|replaced)-(?P<pid>\d+)-[0-9a-f]{8}@(?P<host>.+)$"
)


@dataclass(frozen=True)
class Hidden:
    """A hidden folder of a run: ``partial`` (staging) or ``replaced`` (an old run aside)."""

    path: Path
    name: str
    kind: str
    pid: int
    host: str

    @property
    def target(self) -> Path:
        """The run folder this hidden folder belongs to."""
        return self.path.with_name(self.name)


def default_out(command: str) -> Path:
    """A new folder under ``results/`` named after the command and the time."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    path = Path("results") / f"{command}-{stamp}"
    i = 1
    while path.exists() or path.is_symlink():
        path = Path("results") / f"{command}-{stamp}-{i}"
        i += 1
    return path


def _hidden_name(out: Path, kind: str) -> Path:
    return out.with_name(f".{out.name}.torchsar-{kind}-{os.getpid()}-{secrets.token_hex(4)}@{HOST}")


def hidden_folders(parent: Path) -> list[Hidden]:
    """The hidden staging and moved-aside folders of runs in ``parent`` (any process)."""
    if not parent.is_dir():
        return []
    found = []
    for p in sorted(parent.iterdir()):
        m = _HIDDEN.match(p.name)
        if m and p.is_dir() and not p.is_symlink():
            found.append(Hidden(p, m["name"], m["kind"], int(m["pid"]), m["host"]))
    return found


def _alive(pid: int) -> bool:
    """Whether process ``pid`` of this host still runs (a zombie counts as dead)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True
    return stat.rpartition(")")[2].split()[0] != "Z"


def _settle(h: Hidden) -> None:
    """Finish what the run owning ``h`` left: drop staging; an old run aside is deleted if
    a new run took its place, put back otherwise."""
    if h.kind == "replaced" and not (h.target.exists() or h.target.is_symlink()):
        h.path.rename(h.target)
    else:
        shutil.rmtree(h.path, ignore_errors=True)


def recover(parent: Path, *, keep: str | None = None) -> list[Hidden]:
    """Settle the hidden folders in ``parent`` left by dead runs of this host; returns them.

    Only folders provably ours are touched: named by :func:`result_dir` or :func:`claim`,
    with this host's name and the id of a process that no longer runs. Staging folders of
    the run folder named ``keep`` are left for a resumed run to adopt.
    """
    stale = [
        h
        for h in hidden_folders(Path(parent))
        if h.host == HOST
        and h.pid != os.getpid()
        and not _alive(h.pid)
        and not (h.kind == "partial" and h.name == keep)
    ]
    for h in sorted(stale, key=lambda h: h.kind != "replaced"):  # restore before deleting
        _settle(h)
    return stale


def _is_empty_dir(path: Path) -> bool:
    return path.is_dir() and not path.is_symlink() and next(path.iterdir(), None) is None


def _check_writable(out: Path) -> None:
    """``out``'s nearest existing ancestor must be a folder we can create folders in."""
    anc = out.parent
    while not (anc.exists() or anc.is_symlink()):
        anc = anc.parent
    if not anc.is_dir():
        raise EvalError(f"{{opt:out}}{out}: {anc} is not a folder")
    probe = _hidden_name(anc / "probe", "partial")
    try:
        probe.mkdir()
        probe.rmdir()
    except OSError as exc:
        raise EvalError(f"{{opt:out}}{out}: cannot write in {anc} ({exc.strerror})") from None


def _check_out(out: Path, overwrite: bool) -> None:
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise EvalError(f"{{opt:out}}{out} exists and is not a folder")
    if out.is_dir() and not _is_empty_dir(out):
        if not (out / RUN_MARKER).is_file():
            raise EvalError(
                f"{{opt:out}}{out} is a non-empty folder that is not a run: choose another"
            )
        if not overwrite:
            raise EvalError(
                f"{{opt:out}}{out} holds a previous run: pass {{opt:overwrite}} to replace it"
            )


def check_out(out: Path, *, overwrite: bool = False, resume: bool = False) -> None:
    """:func:`claim`'s checks of ``out``, and what dead runs left beside it settled, without
    touching ``out`` itself (to refuse a bad ``out`` before any other work)."""
    out = Path(out)
    if out.name in ("", ".", ".."):
        raise EvalError(f"{{opt:out}} must name a folder, got {str(out)!r}")
    _check_writable(out)
    recover(out.parent, keep=out.name if resume else None)
    _check_out(out, overwrite)


@contextmanager
def claim(out: Path, *, overwrite: bool = False, resume: bool = False) -> Iterator[Path]:
    """Check ``--out`` before any work and settle what dead runs left beside it.

    Raises :class:`EvalError` when ``out`` is a file, cannot be written, is a non-empty
    folder that is not a run, or holds a previous run and ``overwrite`` is false. With
    ``overwrite``, the previous run is moved aside for the duration: deleted once a new
    run is published at ``out``, put back otherwise (also after a kill: see :func:`recover`).
    With ``resume``, a dead run's staging folder for ``out`` is kept for
    ``result_dir(out, resume=True)``.
    """
    out = Path(out)
    check_out(out, overwrite=overwrite, resume=resume)
    aside = None
    if out.is_dir() and not _is_empty_dir(out):
        aside = _hidden_name(out, "replaced")
        out.rename(aside)
    try:
        yield out
    finally:
        if aside is not None:
            _settle(Hidden(aside, out.name, "replaced", os.getpid(), HOST))


@contextmanager
def result_dir(
    out: Path, *, resume: bool = False, keep_interrupted: bool = False
) -> Iterator[Path]:
    """Yield a hidden staging folder beside ``out``; publish it as ``out`` by one rename.

    ``out`` must be absent or an empty folder (:func:`claim` moves a previous run aside
    first). On any error, Ctrl-C or termination the staging folder is deleted; after a kill,
    the next :func:`claim` in the same parent deletes it. Everything the run writes goes
    into the staging folder, state files included: with ``resume``, the newest staging
    folder a dead run left for ``out`` is adopted (renamed to ours) with its files. With
    ``keep_interrupted``, Ctrl-C and SIGTERM leave the staging folder for a later
    ``resume`` (any other start settles it like a killed run's).
    """
    out = Path(out)
    if out.is_symlink() or (out.exists() and not _is_empty_dir(out)):
        raise EvalError(f"{{opt:out}}{out} already exists and is not an empty folder")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = _hidden_name(out, "partial")
    left = [h for h in hidden_folders(out.parent) if _resumable(h, out)] if resume else []
    if left:
        max(left, key=lambda h: h.path.stat().st_mtime).path.rename(tmp)
    else:
        tmp.mkdir()
    try:
        yield tmp
        _publish(tmp, out)
    except (Exception, KeyboardInterrupt) as exc:
        if not (keep_interrupted and isinstance(exc, KeyboardInterrupt)):
            shutil.rmtree(tmp, ignore_errors=True)
        raise
    except BaseException as exc:  # SIGTERM (raised as an exception by the CLI)
        if not keep_interrupted or isinstance(exc, SystemExit | GeneratorExit):
            shutil.rmtree(tmp, ignore_errors=True)
        raise


def _resumable(h: Hidden, out: Path) -> bool:
    return h.kind == "partial" and h.name == out.name and h.host == HOST and not _alive(h.pid)


def _publish(tmp: Path, out: Path) -> None:
    try:
        os.rename(tmp, out)  # atomic; replaces an empty folder, refuses anything else
    except OSError as exc:
        if exc.errno in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR, errno.EISDIR):
            raise EvalError(f"{{opt:out}}{out} was filled by someone else during the run") from None
        raise EvalError(f"cannot publish the run as {out}: {exc.strerror}") from None


def file_slugs(names: Iterable[str], slug: Callable[[str], str]) -> dict[str, str]:
    """File-name parts for ``names`` that are unique within a run.

    ``slug(name)`` is used where it is unique; names whose slugs collide (two folders
    with the same basename) get their whole name made file-safe instead, then a counter.

    Example:
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


def write_config(folder: Path, command: str, options: dict[str, Any]) -> None:
    """Write ``config.json``: every resolved option plus versions and the command line."""
    cfg = {
        "command": command,
        "argv": sys.argv,
        "torchsar_version": torchsar.__version__,
        "torch_version": torch.__version__,
        "python": platform.python_version(),
        "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "options": options,
    }
    (folder / RUN_MARKER).write_text(json.dumps(cfg, indent=2, default=str) + "\n")
