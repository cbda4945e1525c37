"""Errors of the evaluation harness (user-facing: bad dataset, detector or option)."""

from __future__ import annotations

__all__ = ["EvalError"]


class EvalError(ValueError):
    """A user error in an evaluation request; the message says what to fix."""
