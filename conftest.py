"""Root pytest configuration: names available to every doctest."""

import pytest
import torch

import torchsar


@pytest.fixture(autouse=True)
def _doctest_namespace(doctest_namespace):
    doctest_namespace["torch"] = torch
    doctest_namespace["ts"] = torchsar
    torch.manual_seed(0)
