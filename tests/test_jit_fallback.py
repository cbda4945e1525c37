"""A numba that is installed but cannot be imported falls back to the numpy/torch code
(one warning, the same results), and no script in ``scripts/`` shadows an importable module
(``scripts/coverage.py`` once hid the ``coverage`` package from numba when a script ran)."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest
import torch

import torchsar as ts
from torchsar import _jit

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"


def test_an_unimportable_numba_falls_back_with_one_warning(monkeypatch):
    x = torch.empty(2, 1, 24, 24).exponential_(generator=torch.Generator().manual_seed(0))
    monkeypatch.setattr(_jit, "ENABLED", False)
    want = ts.cfar.os(x)
    monkeypatch.setattr(_jit, "ENABLED", True)
    monkeypatch.setattr(_jit, "_IMPORTS", None)
    monkeypatch.setitem(sys.modules, "numba", None)  # `import numba` raises ImportError
    with pytest.warns(UserWarning, match="numba is installed but cannot be imported"):
        got = ts.cfar.os(x)
    assert torch.equal(got.mask, want.mask) and torch.equal(got.statistic, want.statistic)
    assert _jit.enabled() is False  # tried once, remembered


DEPENDENCIES = ("numba", "scipy", "skimage", "pandas", "kornia", "matplotlib", "tifffile")


def test_no_script_shadows_a_module_that_a_dependency_imports():
    """Running ``python scripts/X.py`` puts ``scripts/`` first on ``sys.path``: a script named
    like a module that a dependency imports, even optionally (``coverage``, which numba
    tries), replaces that module in every process the script starts."""
    stems = sorted(p.stem for p in SCRIPTS.glob("*.py"))
    for stem in stems:
        assert importlib.util.find_spec(stem) is None, f"scripts/{stem}.py: an importable name"
    pattern = re.compile(rf"^\s*(?:import|from)\s+({'|'.join(map(re.escape, stems))})\b", re.M)
    hits = []
    for dep in DEPENDENCIES:
        spec = importlib.util.find_spec(dep)
        if spec is None or not spec.submodule_search_locations:
            continue
        for root in spec.submodule_search_locations:
            for f in Path(root).rglob("*.py"):
                found = pattern.search(f.read_text(errors="ignore"))
                if found:
                    hits.append(f"scripts/{found.group(1)}.py shadows a module {f} imports")
    assert not hits, hits[:5]


def test_the_warm_up_compiles_every_kernel_the_default_run_uses(monkeypatch):
    """``scripts/warm_kernels.py`` (run by ``make setup``) leaves nothing for the default
    evaluation to compile (no kernel gains a signature while it runs), and does nothing
    when the kernels are off."""
    from torchsar import _warm

    monkeypatch.setattr(_jit, "ENABLED", False)
    assert _warm.warm() == 0.0
    monkeypatch.undo()
    if not _jit.enabled():
        pytest.skip("numba is not available")
    import importlib

    from numba.core.registry import CPUDispatcher

    import torchsar_eval as te

    names = [
        "torchsar._windows_kernels",
        "torchsar.cfar._kernels",
        "torchsar.metrics._kernels",
        "torchsar.metrics._match_kernels",
        "torchsar.objects._kernels",
        "torchsar.order_statistics._kernels",
        "torchsar.region._kernels",
    ]

    def compiled() -> dict:
        return {
            (n, k): list(f.signatures)
            for n in names
            for k, f in vars(importlib.import_module(n)).items()
            if isinstance(f, CPUDispatcher)
        }

    assert _warm.warm() > 0
    before = compiled()
    te.evaluate(
        "sim-chips",
        ["ca", "two_parameter", "go", "so", "os", "vi", "ac", "region"],
        n=2,
        progress=False,
    )
    assert compiled() == before


_CHECK_CACHE = """
import sys, torch
from numba.core.registry import CPUDispatcher
import torchsar.metrics._kernels as mk, torchsar._box_kernels as bk
from torchsar._warm import run_task
for task in sys.argv[1:]:
    run_task(task, torch.float32)
found = [f for m in (mk, bk) for f in vars(m).values() if isinstance(f, CPUDispatcher)]
print(sum(sum(f.stats.cache_hits.values()) for f in found),
      sum(sum(f.stats.cache_misses.values()) for f in found))
"""


@pytest.mark.integration
def test_the_parallel_warm_up_fills_the_cache_a_fresh_process_reads(tmp_path):
    """``warm(workers=2)`` compiles its tasks in two processes (their writes into numba's
    cache one at a time): a fresh process then runs the same tasks from the cache alone,
    every kernel a hit and none compiled again."""
    import os
    import subprocess
    import sys

    if not _jit.enabled():
        pytest.skip("numba is not available")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    tasks = ["ca", "lee", "scoring"]
    warm = (
        "import torch; from torchsar._warm import warm; "
        f"print(warm((torch.float32,), workers=2, tasks={tuple(tasks)!r}))"
    )
    subprocess.run([sys.executable, "-c", warm], env=env, check=True, timeout=600)
    run = subprocess.run(
        [sys.executable, "-c", _CHECK_CACHE, *tasks],
        env=env,
        check=True,
        timeout=600,
        capture_output=True,
        text=True,
    )
    hits, misses = map(int, run.stdout.split())
    assert hits > 0 and misses == 0, run.stdout
