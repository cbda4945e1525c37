"""Shared test configuration: deterministic torch, the optional real-data folder, runs
without figures except in the tests about them."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch
from hypothesis import settings

# Without a GPU, the Triton kernels run in Triton's interpreter, which must be chosen before
# anything imports Triton (torchsar's kernels module chooses it too, when it comes first).
if not torch.cuda.is_available():
    os.environ.setdefault("TRITON_INTERPRET", "1")

settings.register_profile("default", max_examples=25, deadline=None, derandomize=True)
settings.load_profile("default")
# One torch thread per pytest-xdist worker (the workers already share the cores: two threads
# each on two cores made torch-heavy tests up to three times slower), else at most two.
torch.set_num_threads(
    1 if os.environ.get("PYTEST_XDIST_WORKER") else min(2, torch.get_num_threads())
)

# A run's curves, gallery and report.html cost about ten times its scoring on a test's few
# images: runs in tests write tables only (TORCHSAR_EVAL_FIGURES=0, inherited by the command
# lines the tests start), except in the tests marked `figures` (a whole module with
# ``pytestmark = pytest.mark.figures``).
FIGURES_ENV = "TORCHSAR_EVAL_FIGURES"
os.environ[FIGURES_ENV] = "0"


def _about_figures(node) -> bool:
    return node.get_closest_marker("figures") is not None


@pytest.fixture(autouse=True, scope="module")
def _module_figures(request):
    """Figures on for a module marked ``figures`` (its module-scoped runs included)."""
    marks = getattr(request.module, "pytestmark", [])
    if not any(m.name == "figures" for m in (marks if isinstance(marks, list) else [marks])):
        yield
        return
    os.environ[FIGURES_ENV] = "1"
    yield
    os.environ[FIGURES_ENV] = "0"


@pytest.fixture(autouse=True)
def _test_figures(request, monkeypatch):
    """Figures on for a test marked ``figures``."""
    if _about_figures(request.node):
        monkeypatch.setenv(FIGURES_ENV, "1")


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
