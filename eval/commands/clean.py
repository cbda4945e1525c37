"""``torchsar-eval clean``: delete the saved work that interrupted runs left.

A run that fails or is interrupted keeps its scored shards in a hidden folder beside its
``--out`` so that ``run --resume`` can continue it; nothing else deletes them. This command
does, for the runs named (or every ended run in the folders named); runs still working are
listed and left alone.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from torchsar_eval.output import RUN_MARKER, clean, hidden_folders

__all__ = ["WRITES_OUT", "add_parser", "run"]

WRITES_OUT = False
"""This command writes no run folder (no ``--out``, no ``--overwrite``)."""


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "clean",
        help="delete the saved work (hidden staging folders) that interrupted runs left",
        description=__doc__.splitlines()[0],
    )
    p.add_argument(
        "targets",
        nargs="*",
        type=Path,
        default=[Path("results")],
        metavar="PATH",
        help="a run folder (its --out, existing or not) or a folder of runs (default: results)",
    )
    p.add_argument("--dry-run", action="store_true", help="list what would be deleted")
    p.set_defaults(func=run, claims_out=True)


def run(args: argparse.Namespace) -> int:
    verb = "would delete" if args.dry_run else "deleted"
    for target in args.targets:
        for h in clean(target, dry_run=args.dry_run):
            what = "an old run moved aside" if h.kind == "replaced" else "saved work"
            print(f"{verb} {what}: {h.describe() if args.dry_run else h.path}")
        parent = target if target.is_dir() and not (target / RUN_MARKER).exists() else None
        for h in hidden_folders(parent or target.parent):
            if h.alive and (parent is not None or h.name == target.name):
                print(f"left {h.path}: its run (process {h.pid} on {h.host}) is still working")
    return 0
