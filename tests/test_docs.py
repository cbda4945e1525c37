"""The documentation's code runs: every ``python`` and ``bash`` block of the tutorials, the
concept pages and the README, in document order, in a fresh folder (a ``python`` block
that opens with ``# file: NAME`` is written to that file instead, for the blocks after it
to import or name). A block right after ``<!-- example: REASON -->`` is skipped (it needs
the reader's own files). The long pages are integration tests (``-m integration``, run by CI); whole scenes and worker pools
run with ``-m slow``."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BLOCK = re.compile(r"(<!-- (?:not run|example):[^>]*-->\s*)?```(python|bash)\n(.*?)```", re.S)
SLOW = {"docs/tutorials/whole-scenes.md", "docs/tutorials/own-detector.md"}
LONG = {"docs/tutorials/results-file.md", "docs/tutorials/cfars-simulated.md", "README.md"}
"""Pages whose runs take 10-20 s: integration tests (CI runs them)."""
PAGES = sorted(
    str(p.relative_to(ROOT))
    for p in [*ROOT.glob("docs/**/*.md"), ROOT / "README.md"]
    if BLOCK.search(p.read_text())
)


def blocks(page: str) -> list[tuple[str, str]]:
    """``(language, code)`` of the page's blocks to run, in order."""
    return [
        (lang, code) for skip, lang, code in BLOCK.findall((ROOT / page).read_text()) if not skip
    ]


def _run_bash(code: str, cwd: Path) -> None:
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    env["MPLBACKEND"] = "Agg"
    done = subprocess.run(
        ["bash", "-euo", "pipefail", "-c", code],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, f"{code}\n{done.stderr[-3000:]}"


@pytest.mark.parametrize(
    "page",
    [
        pytest.param(p, marks=pytest.mark.slow)
        if p in SLOW
        else pytest.param(p, marks=pytest.mark.integration)
        if p in LONG
        else p
        for p in PAGES
    ],
)
def test_the_page_code_runs(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    namespace: dict = {"__name__": "__docs__"}
    for lang, code in blocks(page):
        first = code.split("\n", 1)[0]
        if lang == "python" and first.startswith("# file: "):
            (tmp_path / first[len("# file: ") :].strip()).write_text(code)
        elif lang == "python":
            exec(compile(code, f"{page} (python block)", "exec"), namespace)
        else:
            _run_bash(code, tmp_path)


def test_the_tutorials_are_all_run():
    """Every tutorial has code, and every page with code is in the run above."""
    tutorials = {str(p.relative_to(ROOT)) for p in ROOT.glob("docs/tutorials/*.md")}
    assert tutorials <= set(PAGES)
