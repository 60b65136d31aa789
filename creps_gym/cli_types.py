"""Argument types of the ``creps-gym`` command line: each names what it expected and what it got.

Names that a module may register (``--env``, ``--optimizer``) are checked after ``--import``, in
:mod:`creps_gym.cli`, not here.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Sequence
from typing import Any

__all__ = [
    "UsageError",
    "import_user_modules",
    "initial_mean",
    "integer",
    "key_value",
    "numbers",
    "positive_float",
    "positive_or_none",
    "selector_name",
]


class UsageError(Exception):
    """A bad command line (exit code 2); here so that every command module raises the same class."""


def import_user_modules(modules: Sequence[str]) -> None:
    """Import the ``--import`` modules of any command, searching the current directory for them too.

    The current directory goes last on ``sys.path`` (so a file there never shadows an installed module),
    and only when ``--import`` names a module; nothing is ever imported from a run directory.
    """
    from creps_gym.runner.trust import import_modules

    if modules and os.getcwd() not in sys.path:
        sys.path.append(os.getcwd())
    try:
        import_modules(modules)
    except ValueError as exc:
        raise UsageError(f"argument --import: {exc}") from None


def integer(minimum: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {text!r}")
        return value

    return parse


def positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not 0 < value < math.inf:
        raise argparse.ArgumentTypeError(f"expected a positive finite number, got {text!r}")
    return value


def positive_or_none(text: str) -> float | None:
    if text.lower() == "none":
        return None
    try:
        return positive_float(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"expected a positive finite number or 'none', got {text!r}"
        ) from None


def numbers(text: str) -> float | list[float]:
    try:
        values = [float(part) for part in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a number or comma-separated numbers, got {text!r}"
        ) from None
    return values[0] if len(values) == 1 else values


def initial_mean(text: str) -> str | float | list[float]:
    if text == "uniform":
        return text
    try:
        return numbers(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"expected 'uniform', a number or p comma-separated numbers, got {text!r}"
        ) from None


def key_value(text: str) -> tuple[str, Any]:
    key, sep, raw = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(
            f"expected KEY=VALUE (VALUE in JSON or a plain string), got {text!r}"
        )
    from creps_gym._validation import load_json

    try:
        return key, load_json(raw, key)
    except json.JSONDecodeError:
        return key, raw
    except ValueError as exc:  # nested too deeply
        raise argparse.ArgumentTypeError(str(exc)) from None


def selector_name(text: str) -> str:
    from creps_gym.selectors.registry import selector_names

    if text not in selector_names():
        from creps_gym.listing import did_you_mean

        names = selector_names()
        raise argparse.ArgumentTypeError(f"expected one of {names}, got {text!r}{did_you_mean(text, names)}")
    return text
