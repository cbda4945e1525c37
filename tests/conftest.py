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


@pytest.fixture
def one_thread():
    """One torch thread for the test (the test machine is shared; results do not depend on
    it), restored afterwards."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
