"""Shared test configuration: deterministic torch, the optional real-data folder."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from hypothesis import settings

settings.register_profile("default", max_examples=25, deadline=None, derandomize=True)
settings.load_profile("default")
torch.set_num_threads(min(2, torch.get_num_threads()))

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"


@pytest.fixture
def data_dir() -> Path:
    """The shared real-data folder; tests using it skip when it is absent."""
    if not DATA.is_dir():
        pytest.skip(f"real-data folder {DATA} not present")
    return DATA
