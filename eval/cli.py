"""``torchsar-eval``: the evaluation command line.

``torchsar-eval`` with no arguments is ``torchsar-eval run``: every registered detector on the
default simulated chips and scenes.

One error policy for every command: a user error (a bad option, dataset or output folder)
exits with status 2 and one line ``torchsar-eval: error: ...``; Ctrl-C exits with 130 and
SIGTERM with 143, each with one line, after the run's temporary folders are removed. Any
other exception is a bug and shows its traceback. The heavy imports (torch, the commands)
happen inside :func:`main`, so even an early Ctrl-C gets the one line.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import NoReturn

from torchsar_eval.commands import COMMANDS, load
from torchsar_eval.errors import EvalError, cli_spelling

__all__ = ["Terminated", "build_parser", "main"]

PROG = "torchsar-eval"

FLAGS = {"datasets": "--dataset", "params": "--param", "replicates": "--bootstrap"}
"""Python parameters whose command-line flag is not ``--`` + the name with dashes."""


class Terminated(BaseException):
    """Raised in the main thread when the process receives SIGTERM."""


class _Parser(argparse.ArgumentParser):
    """Argument errors as one line (no usage block), exit status 2."""

    def error(self, message: str) -> NoReturn:
        print(f"{PROG}: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog=PROG,
        description="Evaluate SAR detectors, filters and imaging at dataset scale.",
        epilog="Exit status: 0 done, 2 user error (one line on stderr), 130 interrupted, "
        "143 terminated; --out then holds nothing new.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        module = load(name)
        module.add_parser(sub)
        if not getattr(module, "WRITES_OUT", True):
            continue
        sub.choices[name].add_argument(
            "--overwrite",
            action="store_true",
            help="replace the previous run in --out (refused otherwise)",
        )
    return parser


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = build_parser()
    args = parser.parse_args(argv or ["run"])
    if args.command is None:
        args = parser.parse_args(["run", *argv])
    return args


def _raise_terminated(signum: int, frame: object) -> None:
    raise Terminated


_AGAIN = {Terminated: signal.SIGTERM, KeyboardInterrupt: signal.SIGINT}


def _again_if_swallowed(previous: Callable) -> Callable:
    """An unraisable hook: a :class:`Terminated` or Ctrl-C raised while Python ran a
    finalizer is swallowed there ("Exception ignored in ..."), so send the signal again a
    moment later (from a timer thread, once the finalizer is left) to interrupt the run at
    its next step; anything else goes to ``previous``."""

    def hook(unraisable) -> None:
        for kind, signum in _AGAIN.items():
            if isinstance(unraisable.exc_value, kind):
                again = threading.Timer(0.01, os.kill, (os.getpid(), signum))
                again.daemon = True
                again.start()
                return
        previous(unraisable)

    return hook


@contextmanager
def _signals_raise() -> Iterator[None]:
    """Turn SIGTERM into :class:`Terminated` (so temporary folders are cleaned up), and
    never let it or Ctrl-C be lost in a finalizer."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous, hook = signal.signal(signal.SIGTERM, _raise_terminated), sys.unraisablehook
    sys.unraisablehook = _again_if_swallowed(hook)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
        sys.unraisablehook = hook


LONGEST_WORD = 200
"""Longer runs of non-blank characters in an error (an echoed 100k-character value) are
shortened to their ends, so the error stays one readable line."""


def _elide(word: re.Match) -> str:
    w = word.group(0)
    return f"{w[:60]}...[{len(w) - 80} characters]...{w[-20:]}"


def _user_error(message: object) -> int:
    text = " ".join(line.strip() for line in str(message).strip().splitlines())
    text = re.sub(rf"\S{{{LONGEST_WORD + 1},}}", _elide, text)
    print(f"{PROG}: error: {text}", file=sys.stderr)
    return 2


def _dispatch(args: argparse.Namespace) -> int:
    from torchsar_eval.output import claim, default_out

    out = args.out if getattr(args, "out", None) is not None else default_out(args.command)
    resume = bool(getattr(args, "resume", False))
    if resume and getattr(args, "out", None) is None:
        raise EvalError("--resume needs --out naming the interrupted run's folder")
    if getattr(args, "claims_out", False):  # the command checks and publishes --out itself
        if hasattr(args, "out"):
            args.out = Path(out)
        return int(args.func(args))
    with claim(Path(out), overwrite=args.overwrite, resume=resume) as claimed:
        args.out = claimed
        return int(args.func(args))


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status (2 for user errors, with a one-line message)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        with _signals_raise():
            return _dispatch(_parse(argv))
    except Exception as exc:
        from torchsar._checks import TorchSARError

        if isinstance(exc, EvalError):
            return _user_error(exc.render(cli_spelling(FLAGS)))
        if isinstance(exc, TorchSARError):
            return _user_error(exc)
        raise  # a bug: show the traceback
    except SystemExit as exc:
        if isinstance(exc.code, str):  # commands still raising SystemExit(message)
            raise
        return 0 if exc.code is None else int(exc.code)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted{_resume_hint(argv)}", file=sys.stderr)
        return 130
    except Terminated:
        print(f"{PROG}: terminated{_resume_hint(argv)}", file=sys.stderr)
        return 143


def _resume_hint(argv: list[str]) -> str:
    """How to continue an interrupted ``run`` (its saved shards are kept)."""
    if not argv or argv[0] != "run" or "--out" not in argv:
        return ""
    return "; continue with the same command plus --resume" if "--resume" not in argv else ""


if __name__ == "__main__":
    raise SystemExit(main())
