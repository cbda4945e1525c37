"""The error every reader raises for a file it cannot read as the format it claims, and the
warning for an annotation file that reads but looks wrong."""

from __future__ import annotations

from pathlib import Path

from torchsar._checks import TorchSARError

__all__ = ["AnnotationWarning", "FileFormatError"]


class FileFormatError(TorchSARError, ValueError):
    """A file is missing, unreadable, too large or not the format it claims.

    Attributes:
        path: the offending file (``str``), so callers can skip and count it.
        problem: what is wrong with it, without the path.
    """

    def __init__(self, path: str | Path, problem: str) -> None:
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


class AnnotationWarning(UserWarning):
    """An annotation file reads, but something in it is suspect (a repeated annotation id)."""
