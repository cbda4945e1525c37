"""Shards as Ray tasks, with this run's own torchsar shipped to the workers.

The engine sends copies of the driver's ``torchsar`` and ``torchsar_eval`` packages with the
tasks (Ray's runtime environment ``py_modules``), so cluster nodes need only Python, torch,
numpy and the other dependencies, and Ray — never a ``pip install`` of torchsar, which on
PyPI is another project's name. Before any shard runs, one probe task per detector checks in
a worker that the torchsar it imports is the driver's (same version, same code digest) and
that the detector can be rebuilt there; either failing is refused in one line.
"""

from __future__ import annotations

import atexit
import hashlib
import importlib
import os
import shutil
import sys
import tempfile
from pathlib import Path

import torch

from torchsar_eval.errors import EvalError

__all__ = ["PACKAGES", "package_digest", "run_on_ray", "shipped_packages"]

PACKAGES = ("torchsar", "torchsar_eval")
"""The import packages a Ray worker gets from the driver."""

_SOURCES = ("*.py", "*.json", "*.txt")
_shipped: dict[str, str] = {}


def package_digest(name: str) -> str:
    """A digest of the source files of the imported package ``name`` (its code, not where it
    lies): equal digests mean the same torchsar on both sides."""
    root = Path(importlib.import_module(name).__file__).parent
    h = hashlib.sha256()
    for path in sorted(p for pattern in _SOURCES for p in root.rglob(pattern)):
        if "__pycache__" in path.parts:
            continue
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def shipped_packages() -> list[str]:
    """Folders holding copies of :data:`PACKAGES` under their import names (``eval/`` is
    installed as ``torchsar_eval``), made once per process and removed at exit."""
    if not _shipped:
        tmp = Path(tempfile.mkdtemp(prefix="torchsar-ship-"))
        atexit.register(shutil.rmtree, tmp, ignore_errors=True)
        for name in PACKAGES:
            src = Path(importlib.import_module(name).__file__).parent
            shutil.copytree(src, tmp / name, ignore=shutil.ignore_patterns("__pycache__"))
            _shipped[name] = str(tmp / name)
    return [_shipped[name] for name in PACKAGES]


def _runtime_env(address: str | None) -> dict:
    env: dict = {"py_modules": shipped_packages()}
    if not address:  # a local instance: the driver's path too, for the user's own modules
        env["env_vars"] = {"PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    return env


def _worker_identity() -> dict:
    """In a Ray worker: the torchsar it imports (version, digest, place)."""
    # runs in a Ray worker: its own torchsar, imported there
    import torchsar

    return {
        "version": torchsar.__version__,
        "digests": {name: package_digest(name) for name in PACKAGES},
        "file": torchsar.__file__,
    }


def _arrived(detector) -> None:
    """In a Ray worker: nothing to do; Ray itself rebuilt ``detector`` (its task argument)
    to call this, or failed to."""


def last_line(exc: BaseException) -> str:
    """The last non-blank line of an error's text (a Ray task error ends with the worker's
    own error, e.g. ``ModuleNotFoundError: No module named 'mydets'``).

    Examples:
        >>> last_line(RuntimeError("Traceback:\\n  File x\\nKeyError: 'a'\\n"))
        "KeyError: 'a'"
    """
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    return lines[-1] if lines else type(exc).__name__


def check_workers(ray, detectors: list) -> None:
    """Refuse up front, in one line, a worker whose torchsar differs from the driver's, and
    detectors that a worker cannot rebuild (a module the nodes cannot import)."""
    # the driver's torchsar, compared with the workers' (Ray is an optional extra)
    import torchsar

    probe = ray.remote(num_cpus=1, max_retries=0)
    try:
        seen = ray.get(probe(_worker_identity).remote())
    except Exception as exc:
        reason = " ".join(str(exc).split())[-300:]
        raise EvalError(
            f"the Ray workers cannot import this run's torchsar ({reason}): let the engine "
            "start Ray (it ships torchsar to the workers), or start it yourself with "
            "ray.init(runtime_env={'py_modules': torchsar_eval.ray_engine.shipped_packages()})"
        ) from None
    mine = {name: package_digest(name) for name in PACKAGES}
    if seen["version"] != torchsar.__version__ or seen["digests"] != mine:
        raise EvalError(
            f"the Ray workers import torchsar {seen['version']} from {seen['file']}, not this "
            f"run's torchsar {torchsar.__version__} (other code): remove that installation "
            "from the nodes, or let the engine ship this one (do not set py_modules for "
            "torchsar yourself)"
        )
    for det in detectors:
        try:
            ray.get(probe(_arrived).remote(det))
        except Exception as exc:
            raise EvalError(
                f"detector {det.name} cannot be rebuilt in a Ray worker "
                f"({last_line(exc)}): install its package on every node, or give "
                "Ray its module through runtime_env"
            ) from None


def _scored_one_thread(score, job, k: int) -> bytes:
    torch.set_num_threads(1)  # one Ray CPU per task: never oversubscribe a node
    return score(job, k)


def run_on_ray(job, todo, on_done, fail, address: str | None, score) -> None:
    """Run the shards ``todo`` (``(k, path)`` pairs) as Ray tasks, each ``score(job, k)``
    (the engine's shard scorer, shipped by reference); ``on_done(k, path, data)`` saves each
    result, ``fail`` settles failures (a failed shard runs once more). Ray is started here
    (with this run's packages shipped) unless it already runs."""
    try:
        # Ray is an optional extra: imported only for engine='ray'
        import ray
    except ImportError:
        raise EvalError("{opt:engine}ray needs Ray: pip install 'ray>=2.9'") from None
    if not ray.is_initialized():
        ray.init(
            address=address,
            include_dashboard=False,
            log_to_driver=False,
            configure_logging=False,
            runtime_env=_runtime_env(address),
        )
    check_workers(ray, job.detectors)
    task = ray.remote(num_cpus=1, max_retries=0)(_scored_one_thread)
    refs = {task.remote(score, job, k): (k, path) for k, path in todo}  # retried here, counted
    while refs:
        done, _ = ray.wait(list(refs), num_returns=1)
        k, path = refs.pop(done[0])
        try:
            data = ray.get(done[0])
        except Exception as exc:
            if fail.again(k, exc):
                refs[task.remote(score, job, k)] = (k, path)
                continue
            data = None
        on_done(k, path, data)
