"""The Ray engine ships this run's torchsar to the workers: a worker whose Python has no
torchsar installed (and none on its path) scores the shards with the shipped copy, and a
worker that imports another torchsar is refused in one line."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

DRIVER = """
import json, sys
sys.path.insert(0, {src!r})
import torchsar, torchsar_eval  # from the copy, then off the path: workers cannot see it
sys.path.remove({src!r})
import ray
from torchsar_eval import Execution, evaluate
from torchsar_eval.ray_engine import _worker_identity

kwargs = dict(datasets="sim-chips", detectors=["ca", "region"], n=6, progress=False)
local = evaluate(**kwargs, execution=Execution(shard_size=2, progress=False))
remote = evaluate(**kwargs, execution=Execution(shard_size=2, engine="ray", progress=False))
probe = ray.remote(num_cpus=1)(_worker_identity)
seen = ray.get(probe.remote())
print(json.dumps({{
    "driver": torchsar.__file__,
    "worker": seen["file"],
    "worker_path": ray.get(ray.remote(lambda: __import__("sys").path).remote()),
    "same": local.summary.equals(remote.summary),
    "done": remote.stats["sim-chips"]["done"],
}}))
"""


@pytest.fixture(scope="module")
def bare_python(tmp_path_factory):
    """A Python with torch, Ray and the other dependencies but without torchsar: a venv whose
    only link to ours is a path file naming our site-packages (whose own path files, among
    them torchsar's editable install, are not run from there)."""
    pytest.importorskip("ray")
    venv = tmp_path_factory.mktemp("bare") / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    code = "import sysconfig; print(sysconfig.get_paths()['purelib'])"
    site = subprocess.run(
        [python, "-c", code], capture_output=True, text=True, check=True
    ).stdout.strip()
    Path(site, "deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    check = subprocess.run(
        [python, "-c", "import torch, ray; import torchsar"],
        capture_output=True,
        text=True,
        cwd=venv,
    )
    assert "No module named 'torchsar'" in check.stderr, check.stderr
    return python


@pytest.mark.integration
def test_workers_without_torchsar_score_with_the_shipped_copy(bare_python, tmp_path):
    src = tmp_path / "src"
    skip = shutil.ignore_patterns("__pycache__")
    shutil.copytree(ROOT / "torchsar", src / "torchsar", ignore=skip)
    shutil.copytree(ROOT / "eval", src / "torchsar_eval", ignore=skip)
    script = tmp_path / "driver.py"
    script.write_text(textwrap.dedent(DRIVER.format(src=str(src))))
    # the copy has no compiled-kernel cache: the numpy/torch code spares every process a
    # minute of numba compilation (the kernels are not what is shipped-tested here)
    env = {**os.environ, "TORCHSAR_NUMBA": "0"}
    done = subprocess.run(
        [bare_python, str(script)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=600,
        env=env,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert seen["driver"].startswith(str(src))
    assert not seen["worker"].startswith(str(src)) and "runtime_resources" in seen["worker"]
    assert not any(p.startswith(str(src)) for p in seen["worker_path"])
    assert seen["same"] and seen["done"] == 3


@pytest.mark.integration
def test_a_worker_with_another_torchsar_is_refused(monkeypatch):
    ray = pytest.importorskip("ray")
    from torchsar_eval import ray_engine
    from torchsar_eval.errors import EvalError

    def other_torchsar():
        return {"version": "1.1.4", "digests": {}, "file": "/site-packages/torchsar/__init__.py"}

    monkeypatch.setattr(ray_engine, "_worker_identity", other_torchsar)
    if not ray.is_initialized():
        ray.init(include_dashboard=False, log_to_driver=False, configure_logging=False)
    with pytest.raises(
        EvalError, match=r"import torchsar 1\.1\.4 from /site-packages.*not this run"
    ):
        ray_engine.check_workers(ray, [])
