"""Sub-commands of ``torchsar-eval``: each module has ``add_parser(subparsers)`` and
``run(args) -> int``; :data:`COMMANDS` lists them in help order. The evaluator's commands
live here; the source papers' experiments in :mod:`torchsar_eval.experiments`.

A command's heavy imports (torch, the library, the evaluator's engine and outputs) are inside
its functions: ``torchsar-eval --help`` imports every command's module for its parser and
stays instant, and a command's helper modules are imported by its ``run``."""

from __future__ import annotations

import importlib

__all__ = ["COMMANDS", "EXPERIMENTS", "load"]

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


EXPERIMENTS = frozenset({"pfa", "speckle", "autofocus", "movers", "compare-region"})
"""The sub-commands that are experiments of the source papers (:mod:`torchsar_eval.experiments`)."""


def load(name: str):
    """Import the module of sub-command ``name``."""
    package = "experiments" if name in EXPERIMENTS else "commands"
    return importlib.import_module(f"torchsar_eval.{package}.{name.replace('-', '_')}")
