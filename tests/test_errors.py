"""The project's exceptions have one address, :mod:`creps_gym.errors`: no other module re-exports them."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from creps_gym import errors

PACKAGE = Path(errors.__file__).resolve().parent
ROOT = PACKAGE.parent


def _imports_elsewhere(path: Path) -> list[str]:
    """``from MODULE import NAME`` of a project exception from a module other than ``creps_gym.errors``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return [
        f"{path.relative_to(ROOT)}:{node.lineno}: from {node.module} import {alias.name}"
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("creps_gym")
        for alias in node.names
        if alias.name in errors.__all__ and node.module != "creps_gym.errors"
    ]


def _exported_elsewhere(path: Path) -> list[str]:
    """A project exception named in the ``__all__`` of a module other than ``creps_gym/errors.py``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return [
        f"{path.relative_to(ROOT)}: __all__ names {element.value}"
        for node in tree.body
        if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "__all__" for t in node.targets)
        for element in getattr(node.value, "elts", [])
        if getattr(element, "value", None) in errors.__all__
    ]


def test_no_other_module_re_exports_an_exception() -> None:
    found = [
        line
        for path in sorted(PACKAGE.rglob("*.py"))
        if path != PACKAGE / "errors.py"
        for line in _exported_elsewhere(path)
    ]
    assert not found, "exceptions exported outside creps_gym/errors.py:\n" + "\n".join(found)


@pytest.mark.slow
def test_every_import_of_an_exception_is_from_creps_gym_errors() -> None:
    folders = ("creps_gym", "tests", "benchmarks", "examples", "scripts")
    found = [
        line
        for folder in folders
        for path in sorted((ROOT / folder).rglob("*.py"))
        for line in _imports_elsewhere(path)
    ]
    assert not found, "exceptions imported from another address:\n" + "\n".join(found)


def test_errors_are_what_callers_catch_them_as() -> None:
    assert issubclass(errors.RunDirError, ValueError)
    assert issubclass(errors.RunDirWarning, UserWarning)
    assert issubclass(errors.EpisodeError, RuntimeError)
    assert issubclass(errors.ConfigTypeError, errors.ConfigError) and issubclass(
        errors.ConfigError, ValueError
    )
    assert issubclass(errors.ConfigTypeError, TypeError) and not issubclass(errors.UsageError, ValueError)
    names = ["ConfigError", "ConfigTypeError", "EpisodeError", "RunDirError", "RunDirWarning", "UsageError"]
    assert sorted(errors.__all__) == names


def _exception_classes(source: str) -> list[str]:
    """Classes of ``source`` whose bases are named like exceptions (``...Error``, ``...Warning``, ...)."""
    endings = ("Error", "Exception", "Warning")
    return [
        node.name
        for node in ast.walk(ast.parse(source))
        if isinstance(node, ast.ClassDef)
        and any(getattr(base, "id", getattr(base, "attr", "")).endswith(endings) for base in node.bases)
    ]


def test_every_exception_class_of_the_package_is_defined_in_creps_gym_errors() -> None:
    elsewhere = [
        f"{path.relative_to(PACKAGE.parent)}: {name}"
        for path in sorted(PACKAGE.rglob("*.py"))
        if path.name != "errors.py" or path.parent != PACKAGE
        for name in _exception_classes(path.read_text(encoding="utf-8"))
    ]
    assert not elsewhere, "exception classes outside creps_gym/errors.py:\n" + "\n".join(elsewhere)
