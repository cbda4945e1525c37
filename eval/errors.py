"""Errors of the evaluation harness (user-facing: bad dataset, detector or option).

A message names the option it concerns as ``{opt:NAME}`` (followed by its value, if any,
without a space), NAME being the Python parameter
(``out``, ``workers``, ``overwrite``). ``str(error)`` spells it as in Python (``out=``,
``workers=``, ``overwrite=True``); the command line renders it as its flag (``--out``,
``--workers``, ``--overwrite``) with :meth:`EvalError.render`.

Examples:
    >>> e = EvalError("{opt:out}runs/a holds a previous run: pass {opt:overwrite}")
    >>> str(e)
    'out=runs/a holds a previous run: pass overwrite=True'
    >>> e.render(cli_spelling({"out": "--out", "overwrite": "--overwrite"}, {"overwrite"}))
    '--out runs/a holds a previous run: pass --overwrite'
"""

from __future__ import annotations

import re
from collections.abc import Callable, Container, Mapping

__all__ = ["FLAGS", "EvalError", "cli_spelling", "python_spelling"]

_OPTION = re.compile(r"\{opt:(\w+)\}")

FLAGS = frozenset({"overwrite", "resume", "discard", "skip_bad", "export_coco", "coco_compatible"})
"""Boolean options: named ``NAME=True`` in Python and ``--flag`` on the command line."""


def python_spelling(name: str) -> str:
    """``workers`` -> ``workers=``; a boolean option -> ``overwrite=True``."""
    return f"{name}=True" if name in FLAGS else f"{name}="


def cli_spelling(flags: Mapping[str, str], switches: Container[str] = FLAGS) -> Callable:
    """A spelling by command-line flag (``flags``: parameter -> flag; others: ``--name``),
    followed by a space unless the option is a switch."""

    def spell(name: str) -> str:
        flag = flags.get(name, "--" + name.replace("_", "-"))
        return flag if name in switches else flag + " "

    return spell


class EvalError(ValueError):
    """A user error in an evaluation request; the message says what to fix."""

    def __init__(self, message: str) -> None:
        self.template = str(message)
        super().__init__(self.render(python_spelling))

    def render(self, spell: Callable[[str], str]) -> str:
        """The message with each ``{opt:NAME}`` spelled by ``spell(NAME)``."""
        return _OPTION.sub(lambda m: spell(m.group(1)), self.template)
