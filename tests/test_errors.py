"""The public error types: one module defines them all, each a TorchSARError and the
built-in type a caller would catch; the subpackages re-export the same classes."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import torchsar
from torchsar import errors

ROOT = Path(__file__).resolve().parents[1]
BUILTIN = {
    "InputTypeError": TypeError,
    "ShapeError": ValueError,
    "InputValueError": ValueError,
    "WindowSizeError": ValueError,
    "WindowError": IndexError,
    "OptionError": ValueError,
    "FileFormatError": ValueError,
    "GeorefError": ValueError,
    "UnsettledError": RuntimeError,
}


@pytest.mark.parametrize("name", sorted(BUILTIN))
def test_each_error_is_a_torchsar_error_and_a_builtin_one(name):
    cls = getattr(errors, name)
    assert issubclass(cls, errors.TorchSARError) and issubclass(cls, BUILTIN[name])
    assert name in errors.__all__


def test_subpackages_raise_the_same_classes():
    from torchsar.io import FileFormatError
    from torchsar.io.georef import GeorefError
    from torchsar.io.window import WindowError
    from torchsar.tiling.region import UnsettledError

    assert FileFormatError is errors.FileFormatError and GeorefError is errors.GeorefError
    assert WindowError is errors.WindowError and UnsettledError is errors.UnsettledError
    assert torchsar.errors is errors


def _python_files():
    for top in ("torchsar", "eval", "tests", "scripts"):
        yield from (ROOT / top).rglob("*.py")


def test_error_types_are_defined_once_and_imported_from_their_public_module():
    """No other module defines a TorchSARError subclass, and none imports one from the
    private validation module."""
    names = set(errors.__all__)
    for path in _python_files():
        if path == ROOT / "torchsar" / "errors.py":
            continue
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef) and node.name in names:
                raise AssertionError(f"{path}: defines {node.name} again")
            if isinstance(node, ast.ImportFrom) and node.module == "torchsar._checks":
                bad = {a.name for a in node.names} & names
                assert not bad, f"{path}: imports {bad} from torchsar._checks"
