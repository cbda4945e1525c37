"""``torchsar-eval``: the evaluation command line.

``torchsar-eval`` with no arguments is ``torchsar-eval run``: every registered detector on the
default simulated chips and scenes.
"""

from __future__ import annotations

import argparse
import sys

from eval.commands import COMMANDS, load
from eval.errors import EvalError
from torchsar._checks import TorchSARError

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="torchsar-eval",
        description="Evaluate SAR detectors, filters and imaging at dataset scale.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        load(name).add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status (2 for user errors, with a one-line message)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser()
    args = parser.parse_args(argv or ["run"])
    if args.command is None:
        args = parser.parse_args(["run", *argv])
    try:
        return int(args.func(args))
    except (EvalError, TorchSARError) as exc:
        print(f"torchsar-eval: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
