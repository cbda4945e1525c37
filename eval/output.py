"""Run folders: published whole or not at all, never mixed with an older run.

A command writes its results into a hidden *staging* folder beside ``--out`` and publishes
it with one rename (:func:`result_dir`), so ``--out`` holds either nothing or a complete
run. :func:`claim` checks ``--out`` before any work and, with ``--overwrite``, moves the
previous run aside until the new one is published (then deletes it; on failure it is put
back).

Each hidden folder has a lock file beside it (its name plus ``.lock``) that its process
holds while it works (:mod:`torchsar_eval.locks`): a folder whose lock nobody holds belongs
to a run that ended, however it ended. A resumable run's staging folder (one that holds
``resume.json``) is *never* deleted by anything but its own publication or an explicit
request (``discard``, ``torchsar-eval clean``): an error, a refused resume, a full disk, a
dead worker, Ctrl-C or a kill leave it for ``resume``. What other ended runs left is settled
on the next start in the same parent (:func:`recover`): a staging folder with nothing to
resume is deleted, an old run moved aside is deleted if a new run replaced it and put back
otherwise, resumable staging folders are kept and listed.
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
import stat
import sys
import time
import warnings
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from torchsar_eval.errors import EvalError
from torchsar_eval.locks import LockHeldError, hold, is_held

__all__ = [
    "HOST",
    "Hidden",
    "StaleRunWarning",
    "check_out",
    "claim",
    "clean",
    "default_out",
    "has_saved_work",
    "hidden_folders",
    "not_ours",
    "recover",
    "result_dir",
    "write_config",
    "write_marker",
]

RUN_MARKER = ".torchsar-run.json"
"""Every published run folder holds this file, written last, listing every file the run
wrote; only a folder whose every file it lists is ever replaced (``--overwrite``) or
treated as a run."""
MARKER_TOOL = "torchsar-eval"
_MARKER_BYTES = 64 << 20  # a marker larger than this is not ours
RESUMABLE = "resume.json"
"""The record of a resumable run's options, in its staging folder."""

HOST = re.sub(r"[^A-Za-z0-9.-]+", "_", socket.gethostname()) or "host"
"""This host's name as written in the names of hidden folders (information only)."""
_HIDDEN = re.compile(
    r"^\.(?P<name>.+)\.torchsar-(?P<kind>partial|replaced)-(?P<pid>\d+)-[0-9a-f]{8}@(?P<host>.+?)"
    r"(?P<lock>\.lock)?$"
)


class StaleRunWarning(UserWarning):
    """An ended run left saved work that a ``resume`` can continue."""


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

    @property
    def lock(self) -> Path:
        """The lock file its process holds while it works."""
        return _lock_of(self.path)

    @property
    def alive(self) -> bool:
        """Whether the process that owns it still works on it."""
        return is_held(self.lock)

    @property
    def resumable(self) -> bool:
        """A staging folder with saved work for ``resume``."""
        return self.kind == "partial" and has_saved_work(self.path)

    def describe(self) -> str:
        """``PATH (N saved shards, SIZE)``."""
        files = [p for p in self.path.rglob("*") if p.is_file() and not p.is_symlink()]
        shards = sum(p.suffix == ".state" for p in files)
        size = sum(p.stat().st_size for p in files)
        return f"{self.path} ({shards} saved shard{'s' * (shards != 1)}, {size / 1e6:.1f} MB)"


def has_saved_work(folder: Path) -> bool:
    """Whether a staging folder holds work a ``resume`` would continue: its
    ``resume.json`` and at least one saved shard state."""
    return (folder / RESUMABLE).is_file() and next(folder.rglob("*.state"), None) is not None


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


def _lock_of(hidden: Path) -> Path:
    return hidden.with_name(hidden.name + ".lock")


def hidden_folders(parent: Path) -> list[Hidden]:
    """The hidden staging and moved-aside folders of runs in ``parent`` (any process)."""
    if not parent.is_dir():
        return []
    found = []
    for p in sorted(parent.iterdir()):
        m = _HIDDEN.match(p.name)
        if m and not m["lock"] and p.is_dir() and not p.is_symlink():
            found.append(Hidden(p, m["name"], m["kind"], int(m["pid"]), m["host"]))
    return found


def _stale_locks(parent: Path) -> list[Path]:
    """Lock files whose folder is gone and that nobody holds (a run killed between
    creating its lock and its folder, or while removing them)."""
    if not parent.is_dir():
        return []
    return [
        p
        for p in sorted(parent.iterdir())
        if (m := _HIDDEN.match(p.name))
        and m["lock"]
        and not p.with_name(p.name[: -len(".lock")]).exists()
        and not is_held(p)
    ]


def _settle(h: Hidden) -> None:
    """Finish what the ended run owning ``h`` left: an old run aside is put back if no new
    run took its place and deleted otherwise; a staging folder is deleted."""
    if h.kind == "replaced" and not (h.target.exists() or h.target.is_symlink()):
        h.path.rename(h.target)
    else:
        shutil.rmtree(h.path, ignore_errors=True)


def recover(parent: Path, *, keep: str | None = None) -> list[Hidden]:
    """Settle what ended runs left in ``parent``; returns what was settled.

    Only folders provably ours are touched: named by :func:`result_dir` or :func:`claim`,
    with a lock file nobody holds. Resumable staging folders are never touched: each is
    listed with a :class:`StaleRunWarning` (except those of the run folder ``keep``, which
    the caller resumes or discards).
    """
    parent = Path(parent)
    ended = [h for h in hidden_folders(parent) if not h.alive]
    for h in ended:
        if h.resumable and h.name != keep:
            warnings.warn(
                f"an interrupted run of {h.target} left its saved work in {h.describe()}: "
                f"continue it with --resume --out {h.target}, or delete it with "
                f"'torchsar-eval clean {h.target}'",
                StaleRunWarning,
                stacklevel=2,
            )
    for h in ended:
        if h.lock.exists():
            _remove_lock(h.lock)  # a killed run's lock: nobody holds it
    settle = [h for h in ended if not h.resumable]
    for h in sorted(settle, key=lambda h: h.kind != "replaced"):  # restore before deleting
        _settle(h)
    for lock in _stale_locks(parent):
        _remove_lock(lock)
    return settle


def _remove_lock(lock: Path) -> None:
    """Delete a lock file nobody holds, holding it meanwhile (so that a process creating
    it at the same moment notices and makes a new one)."""
    try:
        with hold(lock):
            pass
    except (LockHeldError, OSError):
        pass  # taken meanwhile: its run is alive


def clean(target: Path, *, dry_run: bool = False) -> list[Hidden]:
    """Delete the saved work that ended runs left: every ended run's hidden folders in the
    folder ``target``, or, when ``target`` names a run folder (existing or not), only that
    run's. Folders of runs still working are never touched. Old runs moved aside are put
    back where nothing replaced them. Returns what was (with ``dry_run``: would be) removed.
    """
    target = Path(target)
    mine = [h for h in hidden_folders(target.parent) if h.name == target.name]
    if target.is_dir() and not (target / RUN_MARKER).is_file() and not mine:
        found = hidden_folders(target)
        parent = target
    else:
        found, parent = mine, target.parent
    ended = [h for h in found if not h.alive]
    if not dry_run:
        for h in sorted(ended, key=lambda h: h.kind != "replaced"):
            _settle(h)
        for lock in _stale_locks(parent):
            _remove_lock(lock)
    return ended


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


def write_marker(folder: Path) -> None:
    """Write :data:`RUN_MARKER` into a finished run folder: every file in it, by path."""
    files = sorted(
        os.path.relpath(os.path.join(d, f), folder)
        for d, _, names in os.walk(folder, followlinks=False)
        for f in names
    )
    record = {"tool": MARKER_TOOL, "files": [f for f in files if f != RUN_MARKER]}
    (folder / RUN_MARKER).write_text(json.dumps(record, indent=0) + "\n")


def not_ours(folder: Path) -> str | None:
    """Why ``folder`` is not a run folder of ours (``None``: it is): no
    :data:`RUN_MARKER`, an unreadable one, or a file or link the marker does not list
    (something a run did not write, and ``--overwrite`` must not delete)."""
    marker = folder / RUN_MARKER
    try:
        st = os.lstat(marker)
    except OSError:
        return f"it has no {RUN_MARKER} (the record every run folder of torchsar-eval holds)"
    if not stat.S_ISREG(st.st_mode) or st.st_size > _MARKER_BYTES:
        return f"its {RUN_MARKER} is not a file a run wrote"
    try:
        record = json.loads(marker.read_text())
        listed = set(record["files"]) if record.get("tool") == MARKER_TOOL else None
    except (OSError, ValueError, TypeError, KeyError, AttributeError, RecursionError):
        listed = None
    if listed is None:
        return f"its {RUN_MARKER} is not a record of torchsar-eval"
    for d, dirs, names in os.walk(folder, followlinks=False):
        for f in sorted(names) + sorted(x for x in dirs if os.path.islink(os.path.join(d, x))):
            rel = os.path.relpath(os.path.join(d, f), folder)
            if rel != RUN_MARKER and rel not in listed:
                return f"it holds {rel}, which no run wrote"
    return None


def _check_out(out: Path, overwrite: bool) -> None:
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise EvalError(f"{{opt:out}}{out} exists and is not a folder")
    if out.is_dir() and not _is_empty_dir(out):
        why = not_ours(out)
        if why is not None:
            raise EvalError(
                f"{{opt:out}}{out} is a non-empty folder that is not a run of torchsar-eval "
                f"({why}): nothing in it is touched; choose another folder"
            )
        if not overwrite:
            raise EvalError(
                f"{{opt:out}}{out} holds a previous run: pass {{opt:overwrite}} to replace it"
            )


def _check_staging(out: Path, resume: bool, discard: bool) -> None:
    """Saved work of an earlier run of ``out`` is continued (``resume``), deleted
    (``discard``) or, with neither, a reason to refuse: a new run would make it unusable."""
    left = [h for h in hidden_folders(out.parent) if h.name == out.name and h.kind == "partial"]
    running = [h for h in left if h.alive]
    if running:
        raise EvalError(
            f"{{opt:out}}{out} is being written by another run (process {running[0].pid} on "
            f"{running[0].host}): wait for it or choose another folder"
        )
    saved = [h for h in left if h.resumable]
    if discard:
        for h in left:
            _settle(h)
    elif saved and not resume:
        raise EvalError(
            f"{{opt:out}}{out}: an interrupted run left its saved work in "
            f"{saved[-1].describe()}: continue it with {{opt:resume}}, or start over "
            f"with {{opt:discard}}"
        )


def check_out(
    out: Path, *, overwrite: bool = False, resume: bool = False, discard: bool = False
) -> None:
    """:func:`claim`'s checks of ``out``, and what ended runs left beside it settled, without
    touching ``out`` itself (to refuse a bad ``out`` before any other work)."""
    out = Path(out)
    if out.name in ("", ".", ".."):
        raise EvalError(f"{{opt:out}} must name a folder, got {str(out)!r}")
    if resume and discard:
        raise EvalError("{opt:resume} and {opt:discard} exclude each other")
    _check_writable(out)
    recover(out.parent, keep=out.name)
    _check_staging(out, resume, discard)
    _check_out(out, overwrite)


@contextmanager
def claim(
    out: Path, *, overwrite: bool = False, resume: bool = False, discard: bool = False
) -> Iterator[Path]:
    """Check ``--out`` before any work and settle what ended runs left beside it.

    Raises :class:`EvalError` when ``out`` is a file, cannot be written, is a non-empty
    folder that is not a run, holds a previous run and ``overwrite`` is false, is being
    written by another run, or has an interrupted run's saved work and neither ``resume``
    (continue it, see ``result_dir(out, resume=True)``) nor ``discard`` (delete it) is
    given. With ``overwrite``, the previous run is moved aside for the duration: deleted
    once a new run is published at ``out``, put back otherwise (also after a kill: see
    :func:`recover`).
    """
    out = Path(out)
    check_out(out, overwrite=overwrite, resume=resume, discard=discard)
    with ExitStack() as stack:
        aside = None
        if out.is_dir() and not _is_empty_dir(out):
            aside = _hidden_name(out, "replaced")
            stack.enter_context(hold(_lock_of(aside)))
            out.rename(aside)
        try:
            yield out
        finally:
            if aside is not None:
                _settle(Hidden(aside, out.name, "replaced", os.getpid(), HOST))


@contextmanager
def result_dir(out: Path, *, resume: bool = False, keep: bool = False) -> Iterator[Path]:
    """Yield a hidden staging folder beside ``out``; publish it as ``out`` by one rename.

    ``out`` must be absent or an empty folder (:func:`claim` moves a previous run aside
    first). Everything the run writes goes into the staging folder, state files included:
    with ``resume``, the newest staging folder an ended run left for ``out`` is adopted
    (renamed to ours) with its files. When the block fails (an error, Ctrl-C, SIGTERM)
    the staging folder is deleted, unless ``keep`` is given and it holds saved work
    (:func:`has_saved_work`): then it is left for a later ``resume`` and an
    :class:`EvalError` says so.
    """
    out = Path(out)
    if out.is_symlink() or (out.exists() and not _is_empty_dir(out)):
        raise EvalError(f"{{opt:out}}{out} already exists and is not an empty folder")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = _hidden_name(out, "partial")
    with hold(_lock_of(tmp)):
        left = [h for h in hidden_folders(out.parent) if _resumable(h, out)] if resume else []
        if left:
            adopted = max(left, key=lambda h: h.path.stat().st_mtime)
            adopted.path.rename(tmp)
            _remove_lock(adopted.lock)
        else:
            tmp.mkdir()
        try:
            yield tmp
            write_marker(tmp)
            _publish(tmp, out)
        except BaseException as exc:
            saved = keep and has_saved_work(tmp)
            if not saved:
                shutil.rmtree(tmp, ignore_errors=True)
            elif isinstance(exc, EvalError):
                raise EvalError(f"{exc.template}; {_kept(tmp)}") from exc
            elif isinstance(exc, OSError):
                raise EvalError(f"cannot write the run ({exc}); {_kept(tmp)}") from exc
            raise


def _kept(tmp: Path) -> str:
    return (
        f"the saved work is kept in {tmp}: continue it with {{opt:resume}} and the same "
        "options, or start over with {opt:discard}"
    )


def _resumable(h: Hidden, out: Path) -> bool:
    return h.kind == "partial" and h.name == out.name and not h.alive


def _publish(tmp: Path, out: Path) -> None:
    try:
        os.rename(tmp, out)  # atomic; replaces an empty folder, refuses anything else
    except OSError as exc:
        if exc.errno in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR, errno.EISDIR):
            raise EvalError(f"{{opt:out}}{out} was filled by someone else during the run") from None
        raise EvalError(f"cannot publish the run as {out}: {exc.strerror}") from None


def write_config(folder: Path, command: str, options: dict[str, Any]) -> None:
    """Write ``config.json``: every resolved option plus versions and the command line."""
    # versions recorded when a folder is written: `clean` imports this module without torch
    import torch

    import torchsar

    cfg = {
        "command": command,
        "argv": sys.argv,
        "torchsar_version": torchsar.__version__,
        "torch_version": torch.__version__,
        "python": platform.python_version(),
        "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "options": options,
    }
    (folder / "config.json").write_text(json.dumps(cfg, indent=2, default=str) + "\n")
