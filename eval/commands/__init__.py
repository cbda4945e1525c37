"""Sub-commands of ``torchsar-eval``: each module has ``add_parser(subparsers)`` and
``run(args) -> int``; :data:`COMMANDS` lists them in help order."""

from __future__ import annotations

import importlib

__all__ = ["COMMANDS", "load"]

COMMANDS = [
    "run",
    "detect",
    "report",
    "pfa",
    "speckle",
    "autofocus",
    "movers",
    "compare-region",
    "make-dataset",
    "clean",
]


def load(name: str):
    """Import the module of sub-command ``name``."""
    return importlib.import_module(f"torchsar_eval.commands.{name.replace('-', '_')}")
