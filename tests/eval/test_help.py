"""The command line's help and start-up: readable help texts, parsers that import nothing
heavy, light constants equal to the live registries, one-line warnings."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import pytest

from torchsar_eval import choices
from torchsar_eval.cli import HelpFormatter, build_parser
from torchsar_eval.commands import COMMANDS

HEAVY = ["torch", "pandas", "matplotlib", "scipy", "skimage", "kornia", "torchsar"]


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(action.choices)


def _help(parser: argparse.ArgumentParser, columns: int, monkeypatch) -> str:
    monkeypatch.setenv("COLUMNS", str(columns))
    return parser.format_help()


@pytest.fixture(scope="module")
def parser() -> argparse.ArgumentParser:
    return build_parser()


def _every_parser(parser):
    return {"torchsar-eval": parser, **_subparsers(parser)}


@pytest.mark.parametrize("columns", [40, 80, 120])
def test_help_never_breaks_a_word_and_has_no_markup(parser, monkeypatch, columns):
    """Wrapped at any width, the help holds the same words as unwrapped (a word broken
    across lines would show as two)."""
    for name, p in _every_parser(parser).items():
        wrapped = _help(p, columns, monkeypatch)
        unwrapped = _help(p, 100_000, monkeypatch)
        assert "``" not in wrapped and ":func:" not in wrapped, name
        assert wrapped.split() == unwrapped.split(), name


def _shown(value) -> set[str]:
    if isinstance(value, float):
        return {f"{value:g}", str(value)}
    if isinstance(value, list | tuple):
        return {" ".join(map(str, value)), ",".join(map(str, value))}
    return {str(value)}


def test_every_option_with_a_default_names_it(parser, monkeypatch):
    for name, p in _subparsers(parser).items():
        text = " ".join(_help(p, 100_000, monkeypatch).split())
        for action in p._actions:
            default = action.default
            if default in (None, argparse.SUPPRESS, []) or isinstance(default, bool):
                continue
            flag = "/".join(action.option_strings) or action.dest
            assert action.help, f"{name} {flag} has a default but no help"
            line = HelpFormatter(name)._get_help_string(action)
            assert "default" in line, f"{name} {flag}: {line!r}"
            shown = any(s in text for s in _shown(default))
            items = str(default).split(",")  # or each item of a default list, in any order
            assert shown or all(i in text for i in items), f"{name} {flag}: {default!r}"


def test_detectors_help_lists_every_name_whole(parser, monkeypatch):
    text = _help(_subparsers(parser)["run"], 40, monkeypatch)
    words = {w.strip(",()") for w in text.split()}
    assert set(choices.BUILTIN_DETECTORS) <= words


def test_parsers_import_nothing_heavy():
    """Building every parser (what --help does) imports no torch, pandas or matplotlib."""
    code = (
        "import json, sys\n"
        "from torchsar_eval.cli import build_parser\n"
        "build_parser().parse_args(['run', '--n', '2'])\n"
        f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout) == []


@pytest.mark.parametrize("command", ["", *COMMANDS])
def test_help_of_every_command_imports_nothing_heavy(command):
    code = (
        "import json, sys\n"
        "from torchsar_eval.cli import main\n"
        f"argv = {[command] if command else []!r} + ['--help']\n"
        "code = main(argv)\n"
        f"print(json.dumps([code, [m for m in {HEAVY!r} if m in sys.modules]]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout.splitlines()[-1]) == [0, []]


def test_light_constants_equal_the_live_ones():
    from torchsar.speckle import FILTERS
    from torchsar_eval.datasets import DATASETS
    from torchsar_eval.experiments.autofocus.experiment import (
        DEFAULT_METHODS,
        ERROR_CASES,
        METHODS,
        Config,
    )
    from torchsar_eval.registry import BUILTIN, available
    from torchsar_eval.result import DEFAULT_MATCH, DEFAULT_RULES

    assert list(choices.BUILTIN_DETECTORS) == list(BUILTIN)
    assert choices.detector_names() == available()
    assert list(choices.DATASET_SCHEMES) == list(DATASETS)
    assert list(choices.SPECKLE_FILTERS) == list(FILTERS)
    rules = DEFAULT_RULES.closing, DEFAULT_RULES.min_area, DEFAULT_RULES.max_area
    assert rules == (choices.DEFAULT_CLOSING, choices.DEFAULT_MIN_AREA, choices.DEFAULT_MAX_AREA)
    assert DEFAULT_MATCH.kind == choices.DEFAULT_MATCH_KIND
    assert list(choices.AUTOFOCUS_ERRORS) == list(ERROR_CASES)
    assert list(choices.AUTOFOCUS_METHODS) == list(METHODS)
    assert list(choices.DEFAULT_AUTOFOCUS_METHODS) == list(DEFAULT_METHODS)
    config = Config()
    assert {k: getattr(config, k) for k in choices.AUTOFOCUS_DEFAULTS} == choices.AUTOFOCUS_DEFAULTS


def test_parser_defaults_equal_the_library_defaults(parser):
    """What the command line passes by default is what the Python API uses by default."""
    from torchsar_eval.experiments.autofocus.experiment import Config
    from torchsar_eval.settings import Calibration, Execution

    run = parser.parse_args(["run"])
    ex = Execution()
    assert (run.batch_size, run.shard_size, run.workers) == (
        ex.batch_size,
        ex.shard_size,
        ex.workers,
    )
    assert run.calibration_fraction == Calibration("f1").fraction
    af = parser.parse_args(["autofocus"])
    cfg = Config()
    assert (af.scenes, af.size, af.density, af.snr, af.seed, af.pfa) == (
        cfg.scenes,
        cfg.size,
        cfg.density,
        cfg.snr_db,
        cfg.seed,
        cfg.pfa,
    )


def test_cli_prints_a_warning_as_one_line(tmp_path):
    """Under the command line a warning is one line without the source line and path;
    outside it, Python's own format is kept."""
    code = (
        "import sys, warnings\n"
        "import torchsar_eval.commands.clean as clean\n"
        "def warn(args):\n"
        "    warnings.warn('first line\\n  second line', UserWarning)\n"
        "    return 0\n"
        "clean.run = warn\n"
        "from torchsar_eval.cli import main\n"
        f"code = main(['clean', {str(tmp_path)!r}])\n"
        "warnings.warn('after main', UserWarning)\n"
        "sys.exit(code)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    lines = out.stderr.splitlines()
    assert lines[0] == "torchsar-eval: warning: first line second line"
    assert "UserWarning: after main" in lines[1]  # library users keep Python's format


@pytest.mark.parametrize("command", COMMANDS)
def test_run_stays_the_command_function_once_its_submodules_are_imported(command):
    """Commands import their heavy submodules when they run; none may be named ``run``
    (importing it would replace the package's ``run`` function)."""
    import importlib
    import inspect
    import pkgutil

    from torchsar_eval.commands import load

    module = load(command)
    for sub in pkgutil.iter_modules(getattr(module, "__path__", [])):
        importlib.import_module(f"{module.__name__}.{sub.name}")
    assert inspect.isfunction(module.run) and inspect.isfunction(module.add_parser)


@pytest.mark.parametrize(
    ("argv", "code"),
    [
        (["run", "--n", "0"], 2),
        (["run", "--workers", "0"], 2),
        (["clean", "--dry-run"], 0),
    ],
)
def test_light_work_imports_no_torch(tmp_path, argv, code):
    """A plain-number mistake fails, and ``clean`` does its work, before torch loads."""
    extra = ["--out", str(tmp_path / "out")] if argv[0] == "run" else [str(tmp_path)]
    script = (
        "import json, sys\n"
        "from torchsar_eval.cli import main\n"
        f"code = main({argv + extra!r})\n"
        f"print(json.dumps([code, [m for m in {HEAVY!r} if m in sys.modules]]))\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert json.loads(out.stdout.splitlines()[-1]) == [code, []], out.stderr
