"""A script that runs an evaluation with workers at its top level (no ``__main__`` guard):
every spawned worker re-imports it and fails before it starts. The run stops with one line
that names the cause, not a "worker died" blamed on the first shard."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest


@pytest.mark.integration
def test_unguarded_script_gets_the_main_guard_message(tmp_path):
    script = tmp_path / "unguarded.py"
    script.write_text(
        textwrap.dedent("""
        from torchsar_eval import Execution, evaluate
        evaluate("sim-chips", ["ca"], n=4, execution=Execution(progress=False, workers=2))
    """)
    )
    out = subprocess.run(
        [sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=600
    )
    assert out.returncode != 0
    last = out.stderr.strip().splitlines()[-1]
    assert last.startswith("torchsar_eval.errors.EvalError: no worker process could start")
    assert 'if __name__ == "__main__":' in last
    assert "died" not in last
