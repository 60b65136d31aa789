"""What a run directory may name: no module is imported on its word, and its text is printed escaped.

**No imports from a run directory.** Gymnasium imports ``module`` for an env id ``"module:Env-v0"``, and
envs that wrap another env (e.g. ``creps_gym/PointMazeGoal-v0``'s ``env`` keyword) pass such ids on. So
the configuration read back from ``config.json`` may only name

* a registered env id, or ``"module:Env-v0"`` whose ``module`` is already imported;
* strings of the form ``"module:..."`` (in the env keywords and optimiser options) whose module is already
  imported;
* a registered optimiser name (the registry never imports a ``"module:Class"`` read from a file).

Anything else raises :class:`~creps_gym.errors.RunDirError` (:func:`check_trusted`). The user imports the
module (``creps-gym resume --import MODULE``, the same for every command, or ``import MODULE`` before
:func:`creps_gym.runner.resume`): :func:`import_modules`, the only code imported on a user's word.

**Text.** A string read from a run directory or a policy file is printed through :func:`escape_text`, so
a control character (an ANSI escape, a newline) never reaches the terminal as it is.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Iterator, Sequence
from typing import Any

import gymnasium as gym

from creps_gym.errors import RunDirError
from creps_gym.optimizers.registry import optimizer_names
from creps_gym.runner.config import RunConfig
from creps_gym.selectors.registry import selector_names

__all__ = [
    "IMPORT_ADVICE",
    "check_trusted",
    "escape_text",
    "import_modules",
    "module_reference",
    "registered_env_id",
    "unimported_module",
]


#: What to do about a module a run directory names; the CLI puts its command in place of ``COMMAND``.
IMPORT_ADVICE = (
    "import the module yourself if you trust it (`creps-gym COMMAND --import MODULE`, or `import MODULE` "
    "in Python first)"
)


def module_reference(text: str) -> str | None:
    """The module a ``"module:name"`` string makes Gymnasium (or a registry) import, or None.

    Gymnasium imports *any* text before the first ``:`` of an env id (``"1evil:X-v0"``, ``"my-evil:X"``,
    ``"évil:X"``, ``" os :X"``), whether or not it is a Python identifier, so every such text counts as
    a module reference, unchanged (no stripping: ``" os"`` is not the module ``os``).
    """
    module, colon, _ = text.partition(":")
    return module if colon else None


def import_modules(modules: Sequence[str]) -> None:
    """Import the modules a user names (``--import``): the only code imported on a user's word."""
    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise ValueError(f"expected an importable module, got {module!r} ({exc})") from None


def registered_env_id(env_id: str, *, import_module: bool = False) -> str:
    """``env_id`` if registered (a ``module:Env-v0``'s module imported first with ``import_module``)."""
    import creps_gym

    module = module_reference(env_id)
    if module is not None and import_module:
        import_modules([module])
    if env_id.split(":", 1)[-1] not in gym.registry:
        raise ValueError(f"expected one of {creps_gym.registered_ids()}, got {env_id!r}")
    return env_id


def _strings(value: Any, where: str) -> Iterator[tuple[str, str]]:
    """Every string in a JSON value (keys included), with where it is."""
    if isinstance(value, str):
        yield where, value
    elif isinstance(value, dict):
        for key, item in value.items():
            yield f"{where}.{key}", str(key)
            yield from _strings(item, f"{where}.{key}")
    elif isinstance(value, (list, tuple)):
        for index, item in enumerate(value):
            yield from _strings(item, f"{where}[{index}]")


def unimported_module(value: Any, where: str) -> tuple[str, str, str] | None:
    """The first string in the JSON ``value`` (keys included) that names a module not imported, or None.

    Returns ``(where in value, the string, the module)``; ``where`` names ``value`` itself.
    """
    for field, text in _strings(value, where):
        module = module_reference(text)
        if module is not None and module not in sys.modules:
            return field, text, module
    return None


def check_trusted(config: RunConfig, source: str) -> None:
    """Refuse a configuration read from ``source`` that would import code (see the module docstring)."""

    def refuse(field: str, value: str, why: str) -> RunDirError:
        return RunDirError(
            f"{source}: {field}: expected {why}, got {value!r}; a run directory never makes the runner "
            f"import code: {IMPORT_ADVICE}"
        )

    if config.optimizer is not None and config.optimizer not in optimizer_names():
        raise refuse("optimizer", config.optimizer, f"a registered optimiser name {optimizer_names()}")
    if config.context_selector is not None and config.context_selector not in selector_names():
        raise refuse("context_selector", config.context_selector, f"a registered selector {selector_names()}")
    for field in ("env", "env_kwargs", "optimizer_options", "context_selector_options"):
        found = unimported_module(getattr(config, field), field)  # config.env None: no string
        if found is not None:
            where, text, module = found
            raise refuse(where, text, f"no reference to a module that is not imported (here {module!r})")
    if config.env is not None and config.env.split(":", 1)[-1] not in gym.registry:  # module imported above
        raise refuse("env", config.env, "a registered env id")
    _check_options_are_data(config, source)


def _check_options_are_data(config: RunConfig, source: str) -> None:
    """Refuse ``cma`` options that pycma would evaluate as code (``{"tolfun": "9**9**9"}``)."""
    if config.optimizer != "cma":  # nevergrad and optuna accept only names from their allow-lists
        return
    from creps_gym.optimizers.adapters.pycma import check_option_value

    options = dict(config.optimizer_options)
    nested = options.pop("cma_options", {})
    for key, value in {**(nested if isinstance(nested, dict) else {}), **options}.items():
        try:
            check_option_value(str(key), value)
        except ValueError as exc:
            raise RunDirError(
                f"{source}: optimizer_options: {exc}; a run directory holds data only"
            ) from None


def escape_text(text: Any) -> str:
    """``str(text)`` safe to print: control characters (ANSI escapes, newlines) as Python escapes."""
    text = str(text)
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)
