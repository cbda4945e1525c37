"""Where the optional real-data samples live: ``../shared/data`` beside the project checkout
(resolved from this file, so the commands find them from any working directory)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["SHARED_DATA"]

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
