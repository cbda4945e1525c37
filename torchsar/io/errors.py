"""The error every reader raises for a file it cannot read as the format it claims, and the
warning for an annotation file that reads but looks wrong."""

from __future__ import annotations

from torchsar.errors import FileFormatError

__all__ = ["AnnotationWarning", "FileFormatError"]


class AnnotationWarning(UserWarning):
    """An annotation file reads, but something in it is suspect (a repeated annotation id)."""
