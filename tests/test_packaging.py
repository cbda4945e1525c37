"""Packaging: every package folder is installed, the harness under its own import name."""

from __future__ import annotations

import importlib.metadata
import importlib.util
import re
import subprocess
import sys
import zipfile
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


def test_the_distribution_has_a_name_of_its_own():
    """``torchsar`` on PyPI is another project: the distribution is ``torchsar-detect`` and
    no instruction anywhere installs ``torchsar`` from an index."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["name"] == "torchsar-detect"
    assert importlib.metadata.version("torchsar-detect") == project["version"]
    pattern = re.compile(r"pip install\s+['\"]?torchsar(\[|['\"\s]|$)", re.M)
    texts = [ROOT / "README.md", ROOT / "Makefile"]
    texts += [*(ROOT / "torchsar").rglob("*.py"), *(ROOT / "eval").rglob("*.py")]
    found = [str(p.relative_to(ROOT)) for p in texts if pattern.search(p.read_text())]
    assert found == []


@pytest.mark.skipif(
    importlib.util.find_spec("setuptools") is None, reason="needs setuptools to build"
)
def test_make_wheel_builds_an_installable_wheel(tmp_path):
    """What ``make wheel`` runs: a wheel named after the distribution, holding both import
    packages and no tests."""
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--quiet",
            "--no-deps",
            "--no-build-isolation",
            "--wheel-dir",
            str(tmp_path),
            str(ROOT),
        ],
        check=True,
        capture_output=True,
        cwd=tmp_path,
    )
    (wheel,) = tmp_path.glob("*.whl")
    assert wheel.name.startswith("torchsar_detect-")
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        meta = z.read(next(n for n in names if n.endswith(".dist-info/METADATA"))).decode()
    assert "Name: torchsar-detect" in meta and "Provides-Extra: ray" in meta
    tops = {n.split("/")[0] for n in names if "/" in n and ".dist-info" not in n}
    assert tops == {"torchsar", "torchsar_eval"}
    assert "torchsar_eval/ray_engine.py" in names and "torchsar/__init__.py" in names


@pytest.mark.integration
def test_a_worker_loads_without_the_table_and_plot_libraries():
    """A worker process imports torchsar and the harness's scoring modules only: pandas,
    kornia and matplotlib (half a second of start-up per process together) are imported
    where they are used, by the driver's tables and plots or a metric that needs them."""
    code = (
        "import sys, torchsar, torchsar_eval.shards, torchsar_eval.registry, "
        "torchsar_eval.store; print(sorted(m for m in ('pandas', 'kornia', 'matplotlib') "
        "if m in sys.modules))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert done.stdout.strip() == "[]"
