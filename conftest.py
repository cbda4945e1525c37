"""Root pytest configuration: names available to every doctest; without numba, the compiled
kernels' modules (which import it) are not collected."""

import importlib.util

import pytest
import torch

import torchsar

collect_ignore_glob = [] if importlib.util.find_spec("numba") else ["torchsar/*/_kernels.py"]


@pytest.fixture(autouse=True)
def _doctest_namespace(doctest_namespace):
    doctest_namespace["torch"] = torch
    doctest_namespace["ts"] = torchsar
    torch.manual_seed(0)
