"""Run the simulator tests single-threaded: small tensors gain nothing from intra-op threads,
and on a shared, loaded machine thread hand-offs dominate their runtime."""

from __future__ import annotations

import pytest
import torch


@pytest.fixture(autouse=True, scope="module")
def _one_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
