"""``torchsar-eval``: the evaluation command line.

``torchsar-eval`` with no arguments is ``torchsar-eval run``: every registered detector on the
default simulated chips and scenes.

One error policy for every command: a user error (a bad option, dataset or output folder)
exits with status 2 and one line ``torchsar-eval: error: ...``; Ctrl-C exits with 130 and
SIGTERM with 143, each with one line, after the run's temporary folders are removed. Any
other exception is a bug and shows its traceback. The heavy imports (torch, the commands)
happen inside :func:`main`, so even an early Ctrl-C gets the one line, and the parsers
import nothing heavy, so ``--help`` is instant. Warnings are printed as one line
``torchsar-eval: warning: ...`` while :func:`main` runs (Python's own format otherwise).
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import sys
import textwrap
import threading
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import NoReturn

from torchsar_eval.commands import COMMANDS, load
from torchsar_eval.errors import EvalError, cli_spelling

__all__ = ["HelpFormatter", "Terminated", "build_parser", "main", "plain"]

PROG = "torchsar-eval"

FLAGS = {"datasets": "--dataset", "params": "--param", "replicates": "--bootstrap"}
"""Python parameters whose command-line flag is not ``--`` + the name with dashes."""


class Terminated(BaseException):
    """Raised in the main thread when the process receives SIGTERM."""


_MARKUP = re.compile(r":\w+:`~?([^`]*)`|``([^`]*)``")
"""Docstring markup (roles such as :func: and double backquotes) that help texts leave out."""


def plain(text: str) -> str:
    """``text`` without docstring markup.

    Examples:
        >>> plain("``torchsar-eval run``: see :func:`~torchsar_eval.evaluate`")
        'torchsar-eval run: see torchsar_eval.evaluate'
    """
    return _MARKUP.sub(lambda m: m.group(1) if m.group(1) is not None else m.group(2), text)


def _shown(value: object) -> str:
    """A default as the help text shows it."""
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, list | tuple):
        return " ".join(map(_shown, value))
    return str(value)


class HelpFormatter(argparse.HelpFormatter):
    """Help without docstring markup, wrapped between words only (never inside a long name),
    and every option's default named, where it has one."""

    def _wrap(self, text: str) -> str:
        return self._whitespace_matcher.sub(" ", plain(text)).strip()

    def _split_lines(self, text: str, width: int) -> list[str]:
        return textwrap.wrap(
            self._wrap(text), width, break_long_words=False, break_on_hyphens=False
        )

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        return textwrap.fill(
            self._wrap(text),
            width,
            initial_indent=indent,
            subsequent_indent=indent,
            break_long_words=False,
            break_on_hyphens=False,
        )

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if (
            "default" in text
            or default is None
            or default is argparse.SUPPRESS
            or isinstance(default, bool)
            or default == []
        ):
            return text
        return f"{text} (default: {_shown(default).replace('%', '%%')})".lstrip()


class _Parser(argparse.ArgumentParser):
    """Argument errors as one line (no usage block), exit status 2; help in
    :class:`HelpFormatter`."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)

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


def _one_line(message: object) -> str:
    text = " ".join(line.strip() for line in str(message).strip().splitlines())
    return re.sub(rf"\S{{{LONGEST_WORD + 1},}}", _elide, text)


def _user_error(message: object) -> int:
    print(f"{PROG}: error: {_one_line(message)}", file=sys.stderr)
    return 2


def _warning_line(message, category, filename, lineno, line=None) -> str:
    """A warning as the command line prints it: one line, without the Python source line
    and the path of the module that warned."""
    return f"{PROG}: warning: {_one_line(message)}\n"


@contextmanager
def _one_line_warnings() -> Iterator[None]:
    """Print warnings as ``torchsar-eval: warning: ...`` for the duration (recorded
    warnings, e.g. under ``warnings.catch_warnings(record=True)``, are not formatted)."""
    previous = warnings.formatwarning
    warnings.formatwarning = _warning_line
    try:
        yield
    finally:
        warnings.formatwarning = previous


def _dispatch(args: argparse.Namespace) -> int:
    # heavy modules inside main only: --help stays instant (see the module's docstring)
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
        with _signals_raise(), _one_line_warnings():
            return _dispatch(_parse(argv))
    except Exception as exc:
        errors = sys.modules.get("torchsar.errors")  # not imported: not a torchsar error
        if isinstance(exc, EvalError):
            return _user_error(exc.render(cli_spelling(FLAGS)))
        if errors is not None and isinstance(exc, errors.TorchSARError):
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
    """How to continue an interrupted ``run`` or ``detect`` (its saved shards or tiles are
    kept)."""
    if not argv or argv[0] not in ("run", "detect") or "--out" not in argv:
        return ""
    return "; continue with the same command plus --resume" if "--resume" not in argv else ""


if __name__ == "__main__":
    raise SystemExit(main())
