"""The compiled speckle filters give the same float64 values whichever filter compiled
first: numba compiles a helper that sets no fastmath with the flags of its first caller,
so before every helper set its own, the moments took FMAs when the Frost kernel compiled
them first (about 100 Lee and 400 Frost pixels of these planes differed). Each order runs
in a fresh process with an empty numba cache (about a minute of compiling)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from torchsar import _jit

pytestmark = [
    pytest.mark.integration,
    pytest.mark.skipif(not _jit.enabled(), reason="numba kernels not available"),
]

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = """
import sys, numpy as np, torch
import torchsar.speckle as sp
g = torch.Generator().manual_seed(3)
x = torch.empty(2, 1, 40, 40, dtype=torch.float64).exponential_(generator=g)
first, second, out = sys.argv[1:4]
a = getattr(sp, first)(x, window=5)
b = getattr(sp, second)(x, window=5)
np.savez(out, **{first: a.numpy(), second: b.numpy()})
"""


def _run(tmp_path: Path, first: str, second: str) -> dict[str, np.ndarray]:
    out = tmp_path / f"{first}-{second}.npz"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / f"cache-{first}")}
    subprocess.run(
        [sys.executable, "-c", SCRIPT, first, second, str(out)],
        check=True,
        cwd=ROOT,
        env=env,
        timeout=600,
    )
    return dict(np.load(out))


def test_the_filters_do_not_depend_on_which_compiled_first(tmp_path):
    one = _run(tmp_path, "lee", "enhanced_frost")
    two = _run(tmp_path, "enhanced_frost", "lee")
    for name in ("lee", "enhanced_frost"):
        assert np.array_equal(one[name], two[name]), name
