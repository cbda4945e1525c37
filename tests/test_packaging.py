"""Packaging: every package folder is installed, the harness under its own import name."""

from __future__ import annotations

import importlib.metadata
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib")  # Python >= 3.11

ROOT = Path(__file__).resolve().parents[1]


def _packages(folder: str, name: str) -> set[str]:
    out = set()
    for init in (ROOT / folder).rglob("__init__.py"):
        rel = init.parent.relative_to(ROOT / folder)
        out.add(".".join([name, *rel.parts]))
    return out


def test_every_package_folder_is_listed():
    setup = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert setup["package-dir"] == {"torchsar_eval": "eval"}
    on_disk = _packages("torchsar", "torchsar") | _packages("eval", "torchsar_eval")
    assert set(setup["packages"]) == on_disk


def test_harness_installs_as_torchsar_eval():
    import torchsar_eval

    assert Path(torchsar_eval.__file__).resolve().parent == ROOT / "eval"
    scripts = importlib.metadata.entry_points(group="console_scripts")
    assert {e.value for e in scripts if e.name == "torchsar-eval"} == {"torchsar_eval.cli:main"}
