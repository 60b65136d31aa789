"""The project's exceptions have one home, :mod:`creps_gym.errors`; the old addresses re-export them."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

from creps_gym import errors

PACKAGE = Path(errors.__file__).resolve().parent
#: Re-exports kept so that code importing from the old addresses keeps working (the same class objects).
OLD_ADDRESSES = {
    "creps_gym.runner": ("EpisodeError", "RunDirError", "RunDirWarning"),
    "creps_gym.runner.errors": ("RunDirError", "RunDirWarning"),
    "creps_gym.runner.session": ("RunDirError", "RunDirWarning"),
    "creps_gym.runner.rundir": ("RunDirError", "RunDirWarning"),
    "creps_gym.runner.episodes": ("EpisodeError",),
    "creps_gym.runner.backends": ("EpisodeError",),
    "creps_gym.runner.config": ("ConfigError", "ConfigTypeError"),
    "creps_gym._validation": ("ConfigError", "ConfigTypeError"),
    "creps_gym.cli.types": ("UsageError",),
}


@pytest.mark.parametrize("module", sorted(OLD_ADDRESSES))
def test_an_old_address_re_exports_the_same_class(module: str) -> None:
    imported = importlib.import_module(module)
    for name in OLD_ADDRESSES[module]:
        assert getattr(imported, name) is getattr(errors, name), (module, name)
        assert name in imported.__all__, (module, name)


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
