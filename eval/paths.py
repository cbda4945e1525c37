"""Where the optional real-data samples live: the folder named by ``TORCHSAR_DATA``, else
``../shared/data`` beside a source checkout (found from this file, so the commands find
them from any working directory). An installed package has no checkout beside it: without
``TORCHSAR_DATA`` the commands that use the samples skip them with a note."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["SHARED_DATA", "shared_data"]


def shared_data() -> Path:
    """The real-data folder (it may not exist: callers skip what they cannot find)."""
    given = os.environ.get("TORCHSAR_DATA")
    if given:
        return Path(given)
    checkout = Path(__file__).resolve().parents[1]
    if (checkout / "pyproject.toml").is_file():  # a source checkout: its sibling folder
        return checkout.parent / "shared" / "data"
    return Path("shared") / "data"  # relative: found only where the user runs it


SHARED_DATA = shared_data()
""":func:`shared_data` when the harness was imported."""
