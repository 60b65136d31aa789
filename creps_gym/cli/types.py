"""Argument types of the ``creps-gym`` command line: each names what it expected and what it got.

Also what every command module shares: :class:`UsageError` (exit code 2), the ``--import`` flag and the
imports it asks for, the ``KEY=VALUE`` flags. Names that a module may register (``--env``, ``--optimizer``)
are checked after ``--import`` (:func:`import_modules_and_check_names`), not by their argument types.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Sequence
from typing import Any

from creps_gym.errors import UsageError

__all__ = [
    "add_import",
    "add_key_value",
    "add_search_start",
    "import_modules_and_check_names",
    "import_user_modules",
    "initial_mean",
    "integer",
    "key_value",
    "numbers",
    "positive_float",
    "positive_or_none",
    "selector_name",
]

_INITIAL_MEAN_HELP = "a number, p comma-separated numbers, or 'uniform' in the box"


def import_user_modules(modules: Sequence[str]) -> None:
    """Import the ``--import`` modules of any command, searching the current directory for them too.

    The current directory goes last on ``sys.path`` (so a file there never shadows an installed module),
    and only when ``--import`` names a module; nothing is ever imported from a run directory.
    """
    from creps_gym.runner.rundir.references import import_modules

    if modules and os.getcwd() not in sys.path:
        sys.path.append(os.getcwd())
    try:
        import_modules(modules)
    except ValueError as exc:
        raise UsageError(f"argument --import: {exc}") from None


def add_import(parser: argparse.ArgumentParser) -> None:
    """The ``--import MODULE`` flag (repeatable) of every command that may need a user's module."""
    parser.add_argument(
        "--import",
        dest="imports",
        action="append",
        default=[],
        metavar="MODULE",
        help="import MODULE first (e.g. the module that registers your env or optimiser; repeatable; "
        "searched in the current directory too); a run directory never makes creps-gym import anything",
    )


def add_key_value(parser: Any, flag: str, text: str) -> None:
    """A repeatable ``KEY=VALUE`` flag (``--opt``, ``--env-kwarg``, ``--selector-opt``), parsed by
    :func:`key_value` into a list of pairs; ``text`` starts its help."""
    parser.add_argument(
        flag,
        action="append",
        type=key_value,
        default=[],
        metavar="KEY=VALUE",
        help=f"{text}; VALUE is JSON or a string (repeatable)",
    )


def add_search_start(parser: Any, mean: Any = None, std: Any = None) -> None:
    """``--initial-mean`` and ``--initial-std``, the search distribution's start (``run``, ``ask --new``).

    ``mean`` and ``std`` are their defaults; ``None`` means the env-declared ones (the box rule for an env
    that declares none, as an ask/tell run's boxes).
    """
    flags = (
        ("--initial-mean", initial_mean, _INITIAL_MEAN_HELP, mean, "the env-declared mean"),
        ("--initial-std", numbers, "initial standard deviation(s)", std, "the env-declared one"),
    )
    for flag, parse, text, default, if_none in flags:
        shown = if_none if default is None else default
        parser.add_argument(flag, type=parse, default=default, help=f"{text} (default: {shown})")


def import_modules_and_check_names(args: argparse.Namespace) -> None:
    """Import the ``--import`` modules, then check the names they may register: ``--env`` (a
    ``module:Env-v0``'s module is imported) and ``--optimizer``.

    The current directory is searched for an ``--import`` module, after every other path entry (so it
    never shadows an installed module); nothing is ever imported from a run directory.
    """
    from creps_gym.runner.rundir.references import registered_env_id

    import_user_modules(args.imports)
    if getattr(args, "env", None) is not None:
        try:
            registered_env_id(args.env, import_module=True)
        except ValueError as exc:
            unknown = str(exc).startswith("expected one of")  # else: its module cannot be imported
            raise UsageError(f"argument --env: {_unknown_env(args.env) if unknown else exc}") from None
    if getattr(args, "optimizer", None) is not None:
        try:
            _registered_optimizer(args.optimizer)
        except ValueError as exc:
            raise UsageError(f"argument --optimizer: {exc}") from None


def _unknown_env(env_id: str) -> str:
    """The hint first (a short line), then the registered ids, wrapped."""
    import textwrap

    import creps_gym
    from creps_gym._suggest import did_you_mean

    ids = creps_gym.registered_ids()
    listing = textwrap.fill(", ".join(ids), width=100, initial_indent="  ", subsequent_indent="  ")
    return (
        f"unknown env id {env_id!r}{did_you_mean(env_id, ids)}\n"
        f"expected one of these ids (`creps-gym list` describes them) or module:Env-v0:\n{listing}"
    )


def _registered_optimizer(name: str) -> None:
    from creps_gym._suggest import did_you_mean
    from creps_gym.optimizers.registry import optimizer_names

    names = optimizer_names()
    if name not in names:
        raise ValueError(f"expected one of {names}, got {name!r}{did_you_mean(name, names)}")


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
        from creps_gym._suggest import did_you_mean

        names = selector_names()
        raise argparse.ArgumentTypeError(f"expected one of {names}, got {text!r}{did_you_mean(text, names)}")
    return text
