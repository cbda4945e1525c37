"""The README's examples of "Evaluate your own detector", "Score saved predictions" and "Use
it in a training loop" run
as written (in a temporary folder): files it shows are written, Python blocks executed,
``torchsar-eval`` lines run; a block marked ``<!-- example: ... -->`` is only shown."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
SECTIONS = (
    "## Evaluate your own detector",
    "## Score saved predictions",
    "## Use it in a training loop",
)
BLOCK = re.compile(r"(<!-- example:[^>]*-->\n)?```(\w+)\n(.*?)```", re.DOTALL)


def _blocks() -> list[tuple[str, str]]:
    text = README.read_text()
    out = []
    for head in SECTIONS:
        start = text.index(head)
        end = text.find("\n## ", start + len(head))
        for shown_only, lang, body in BLOCK.findall(text[start : end if end > 0 else None]):
            if not shown_only:
                out.append((lang, body))
    return out


def test_the_sections_have_runnable_examples():
    langs = [lang for lang, _ in _blocks()]
    assert langs.count("python") >= 3 and langs.count("bash") >= 2


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_readme_examples_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), *sys.path])}
    for lang, body in _blocks():
        first = body.splitlines()[0]
        if lang == "python" and first.startswith("# file: "):
            (tmp_path / first.removeprefix("# file: ").strip()).write_text(body)
        elif lang == "python":
            exec(compile(body, "README.md", "exec"), {"__name__": "readme"})
        elif lang == "bash":
            for line in body.splitlines():
                if line.startswith("torchsar-eval "):
                    argv = [sys.executable, "-m", "torchsar_eval.cli", *shlex.split(line)[1:]]
                    done = subprocess.run(
                        [*argv, "--no-progress"],
                        cwd=tmp_path,
                        env=env,
                        capture_output=True,
                        text=True,
                        timeout=600,
                    )
                    assert done.returncode == 0, f"{line}\n{done.stderr}"
    assert (tmp_path / "results" / "mine" / "summary.csv").is_file()
    assert (tmp_path / "results" / "saved" / "summary.csv").is_file()
