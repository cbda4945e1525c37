"""Result folders: written atomically (no partial output on failure), with the config."""

from __future__ import annotations

import json
import platform
import shutil
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import torch

import torchsar

__all__ = ["default_out", "result_dir", "write_config"]


def default_out(command: str) -> Path:
    """A new folder under ``results/`` named after the command and the time."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    path = Path("results") / f"{command}-{stamp}"
    i = 1
    while path.exists():
        path = Path("results") / f"{command}-{stamp}-{i}"
        i += 1
    return path


@contextmanager
def result_dir(out: Path) -> Iterator[Path]:
    """Yield a temporary folder; on success move its files into ``out``, on error delete it.

    So a failed run (bad input discovered mid-way, an exception, Ctrl-C) leaves nothing
    behind, and a successful one replaces same-named files in ``out``.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    out.mkdir(parents=True, exist_ok=True)
    for f in tmp.iterdir():
        f.replace(out / f.name)
    tmp.rmdir()


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
    (folder / "config.json").write_text(json.dumps(cfg, indent=2, default=str) + "\n")
