"""The import graph: no cycle anywhere (imports inside functions counted too, ``if
TYPE_CHECKING`` blocks not), the library's units in layers that import only downward, the
harness's modules in layers (datasets -> scoring -> engine -> outputs -> command line) that
import only downward, and the library never importing the harness."""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

LIBRARY = {
    # the shared base: errors, validation, seeding, the detector types
    "errors": 0,
    "_scale": 0,
    "_jit": 0,
    "_triton": 1,
    "_disk_cache": 0,
    "_block_sums": 0,
    "_vector_exp": 1,
    "_moment_kernels": 1,
    "_box_kernels": 2,
    "_pinwheel_kernels": 1,
    "_gpu_kernels": 0,
    "_shell_kernels": 2,
    "_windows_kernels": 0,
    "detection": 0,
    "_checks": 1,
    "catalog": 1,
    # primitives: seeding, windows and their sums, readers, objects
    "seeding": 2,
    "windows": 2,
    "io": 2,
    "objects": 2,
    "simulate": 3,
    "order_statistics": 3,
    "speckle": 3,
    "sar": 3,
    "metrics": 3,
    # detectors and imaging
    "cfar": 4,
    "region": 4,
    "imaging": 4,
    # pipelines on top of them
    "motion": 5,
    "tiling": 5,
    "_warm": 6,
    "": 7,
}
"""Each unit of ``torchsar`` (a subpackage or top-level module; ``""``: the package root) and
its layer: a unit imports only units of lower layers."""

HARNESS = {
    "base": [
        "errors",
        "choices",
        "paths",
        "names",
        "labels",
        "memory",
        "npy",
        "locks",
        "statefile",
        "colours",
        "glossary",
        "calibrate",
    ],
    "datasets": ["datasets", "store", "items", "inputs", "batches"],
    "scoring": [
        "detector",
        "registry",
        "options",
        "sweep",
        "settings",
        "saved",
        "scoring",
        "tables",
        "results",
        "result",
        "gallery",
        "coco",
        "objects_only",
    ],
    "engine": ["runner", "pool", "ray_engine", "shard_states", "shards", "resume", "output"],
    "outputs": [
        "leaderboard",
        "latex",
        "plots",
        "panels",
        "html_report",
        "overlays",
        "report",
        "api",
    ],
    "cli": ["cli", "commands", "experiments", ""],
}
"""The harness's layers, lowest first, with the modules (or subpackages) in each; a module
imports only modules of its own layer or lower ones."""


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    parts[0] = "torchsar_eval" if parts[0] == "eval" else parts[0]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


@cache
def graph() -> dict[str, set[str]]:
    """Every module of ``torchsar`` and ``torchsar_eval`` and the modules of both it imports
    (at module level or inside a function)."""
    files = {_module_name(p): p for top in ("torchsar", "eval") for p in (ROOT / top).rglob("*.py")}

    def resolve(name: str) -> str | None:
        while name and name not in files:
            name = name.rpartition(".")[0]
        return name or None

    def imported(node: ast.AST, package: str) -> set[str]:
        """The modules ``node``'s imports name, at any depth (``if TYPE_CHECKING`` blocks
        left out; relative imports read from ``package``)."""
        found: set[str] = set()
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                continue
            if isinstance(child, ast.Import):
                names = [a.name for a in child.names]
            elif isinstance(child, ast.ImportFrom):
                base = child.module or ""
                if child.level:
                    up = package.split(".")[: len(package.split(".")) - child.level + 1]
                    base = ".".join([*up, base] if base else up)
                subs = [f"{base}.{a.name}" for a in child.names]
                names = [s for s in subs if s in files] or [base]
            else:
                found |= imported(child, package)
                continue
            found.update(r for r in map(resolve, names) if r)
        return found

    out: dict[str, set[str]] = {}
    for mod, path in files.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        out[mod] = imported(ast.parse(path.read_text(), str(path)), package) - {mod}
    return out


def _cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []
    for root in g:
        if root in index:
            continue
        work = [(root, iter(sorted(g[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(g[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    x = stack.pop()
                    on.discard(x)
                    comp.append(x)
                    if x == v:
                        break
                if len(comp) > 1:
                    found.append(sorted(comp))
    return found


def test_no_import_cycle():
    assert _cycles(graph()) == []


def test_the_cycle_finder_finds_one():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def _unit(mod: str) -> str:
    return mod.split(".")[1] if "." in mod else ""


def test_the_library_imports_downward_and_never_the_harness():
    bad = []
    for mod, deps in graph().items():
        if not mod.startswith("torchsar") or mod.startswith("torchsar_eval"):
            continue
        assert _unit(mod) in LIBRARY, f"{mod}: give its unit a layer"
        for dep in deps:
            assert not dep.startswith("torchsar_eval"), f"{mod} imports the harness ({dep})"
            if _unit(dep) != _unit(mod) and LIBRARY[_unit(dep)] >= LIBRARY[_unit(mod)]:
                bad.append(f"{mod} -> {dep}")
    assert bad == []


def _layer(mod: str) -> int:
    name = mod.removeprefix("torchsar_eval").removeprefix(".")
    for rank, members in enumerate(HARNESS.values()):
        if any(name == m or (m and name.startswith(m + ".")) for m in members):
            return rank
    raise AssertionError(f"{mod}: give it a layer")


def test_the_harness_imports_downward():
    bad = []
    for mod, deps in graph().items():
        if not mod.startswith("torchsar_eval"):
            continue
        for dep in deps:
            if dep.startswith("torchsar_eval") and _layer(dep) > _layer(mod):
                bad.append(f"{mod} ({_layer(mod)}) -> {dep} ({_layer(dep)})")
    assert bad == []


def test_the_evaluator_never_imports_the_experiments():
    """The papers' experiments use the evaluator; the evaluator (its commands included)
    reaches them only by name, through the command table."""
    bad = [
        f"{mod} -> {dep}"
        for mod, deps in graph().items()
        if mod.startswith("torchsar_eval") and not mod.startswith("torchsar_eval.experiments")
        for dep in deps
        if dep.startswith("torchsar_eval.experiments")
    ]
    assert bad == []
    assert any(m.startswith("torchsar_eval.experiments.") for m in graph())


def _inner_imports(path: Path) -> list[tuple[int, str]]:
    """``(line, function)`` of every import inside a function of ``path``."""
    tree = ast.parse(path.read_text(), str(path))
    return [
        (child.lineno, node.name)
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        for child in ast.walk(node)
        if isinstance(child, ast.Import | ast.ImportFrom)
    ]


def _said(lines: list[str], lineno: int) -> bool:
    """A comment on the import's line, or on the line above its block of imports."""
    i = lineno - 1
    if "#" in lines[i]:
        return True
    while i > 0 and (
        not lines[i - 1].strip() or lines[i - 1].strip().startswith(("import ", "from "))
    ):
        i -= 1
    return i > 0 and lines[i - 1].strip().startswith("#")


def test_every_import_inside_a_function_says_why():
    """An import inside a function keeps a start-up light (``--help``, a worker process
    without pandas or matplotlib) or an optional dependency optional: the sub-commands'
    packages say so once (``--help`` imports every command's parser), every other one on
    its line or above its block."""
    for package in ("commands", "experiments"):
        assert "--help" in (ROOT / "eval" / package / "__init__.py").read_text()
    bad = []
    for path in sorted((ROOT / "eval").rglob("*.py")):
        if {"commands", "experiments"} & set(path.relative_to(ROOT / "eval").parts):
            continue
        lines = path.read_text().splitlines()
        bad += [
            f"{path.relative_to(ROOT)}:{n} ({fn})"
            for n, fn in _inner_imports(path)
            if not _said(lines, n)
        ]
    assert bad == []
