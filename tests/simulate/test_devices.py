"""Every simulator checks its device at the entry (a clear OptionError naming it)."""

from __future__ import annotations

import pytest
import torch

from torchsar.errors import OptionError
from torchsar.simulate import chips, clutter, scenes

MAKERS = [
    lambda **kw: chips(1, **kw),
    lambda **kw: scenes(1, **kw),
    lambda **kw: clutter((2, 2), **kw),
]


@pytest.mark.skipif(torch.cuda.is_available(), reason="needs a machine without a GPU")
@pytest.mark.parametrize("make", MAKERS)
def test_unavailable_device(make):
    with pytest.raises(OptionError, match="device = 'cuda' is not available.*device='cpu'"):
        make(device="cuda")


@pytest.mark.parametrize("make", MAKERS)
@pytest.mark.parametrize("device", ["nodevice", 3.5])
def test_not_a_device(make, device):
    with pytest.raises(OptionError, match="device must be a torch.device"):
        make(device=device)


def test_cpu_device_object():
    assert clutter((2, 2), device=torch.device("cpu")).device.type == "cpu"
