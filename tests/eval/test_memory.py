import subprocess
import sys

import pytest
import torch

from torchsar_eval.memory import _libc, release_memory

glibc = pytest.mark.skipif(_libc() is None, reason="needs glibc")

_FAULTS = """
import resource, sys
import numpy as np
from torchsar_eval.memory import tune_allocator
if sys.argv[1] == "tuned":
    assert tune_allocator()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    live = [np.ones(1 << 17) for _ in range(16)]  # sixteen 1 MB temporaries at once
    del live
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""
_PAGES = 16 * (1 << 20) // 4096  # pages touched by one round


def _faults(mode: str) -> int:
    out = subprocess.run([sys.executable, "-c", _FAULTS, mode], capture_output=True, check=True)
    return int(out.stdout)


def test_release_memory_is_harmless():
    """Trimming the allocator after a shard frees nothing still in use."""
    x = torch.arange(10.0)
    assert isinstance(release_memory(), bool)
    assert torch.equal(x, torch.arange(10.0))


@glibc
def test_tuned_allocator_reuses_pages():
    """A batch's temporaries freed together and allocated again: by default glibc gives the
    freed heap back and every round faults in fresh pages; tuned, the rounds reuse the
    first round's pages."""
    tuned = _faults("tuned")
    assert tuned < 2 * _PAGES
    assert _faults("default") > 5 * tuned
