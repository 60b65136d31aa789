"""A run directory is untrusted input: what it may name, and how big a run may be.

**No imports from a run directory.** Gymnasium imports ``module`` for an env id ``"module:Env-v0"``, and
envs that wrap another env (e.g. ``creps_gym/PointMazeGoal-v0``'s ``env`` keyword) pass such ids on. So
the configuration read back from ``config.json`` may only name

* a registered env id, or ``"module:Env-v0"`` whose ``module`` is already imported;
* strings of the form ``"module:..."`` (in the env keywords and optimiser options) whose module is already
  imported;
* a registered optimiser name (the registry never imports a ``"module:Class"`` read from a file).

Anything else raises :class:`~creps_gym.runner.session.RunDirError`. The user imports the module
(``creps-gym resume --import MODULE``, or ``import MODULE`` before :func:`creps_gym.runner.resume`).

**Sizes.** :func:`check_run_memory` refuses, before the optimiser or the batch is allocated, a run whose
arrays would not fit in memory (:func:`creps_gym._validation.check_fits_in_memory`).
"""

from __future__ import annotations

import importlib
import re
import sys
from collections.abc import Iterator, Sequence
from typing import Any

import gymnasium as gym

from creps_gym._validation import check_fits_in_memory
from creps_gym.optimizers.registry import optimizer_names
from creps_gym.runner.config import RunConfig
from creps_gym.runner.session import RunDirError

__all__ = ["check_run_memory", "check_trusted", "import_modules", "module_reference", "registered_env_id"]

_MODULE_PREFIX = re.compile(r"^\s*([A-Za-z_][\w.]*)\s*:")


def module_reference(text: str) -> str | None:
    """The module a ``"module:name"`` string makes Gymnasium (or a registry) import, or None."""
    match = _MODULE_PREFIX.match(text)
    return match.group(1) if match else None


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


def check_trusted(config: RunConfig, source: str) -> None:
    """Refuse a configuration read from ``source`` that would import code (see the module docstring)."""

    def refuse(field: str, value: str, why: str) -> RunDirError:
        return RunDirError(
            f"{source}: {field}: expected {why}, got {value!r}; a run directory never makes the runner "
            "import code: import the module yourself (`creps-gym resume --import MODULE`, or `import "
            "MODULE` before `resume`) if you trust it"
        )

    if config.optimizer is not None and config.optimizer not in optimizer_names():
        raise refuse("optimizer", config.optimizer, f"a registered optimiser name {optimizer_names()}")
    found = [("env", config.env)] if config.env is not None else []
    found += _strings(config.env_kwargs, "env_kwargs")
    found += _strings(config.optimizer_options, "optimizer_options")
    for field, text in found:
        module = module_reference(text)
        if module is not None and module not in sys.modules:
            raise refuse(field, text, f"no reference to a module that is not imported (here {module!r})")
    if config.env is not None and module_reference(config.env) is None and config.env not in gym.registry:
        raise refuse("env", config.env, "a registered env id")


def check_run_memory(config: RunConfig, n_params: int, n_context_dims: int, *, covariance: bool) -> None:
    """Refuse a run whose optimiser and batch arrays would not fit in memory, before they are allocated.

    The estimate counts 8-byte floats: about ``6 p²`` for a covariance and its factors (when
    ``covariance``), ``4 N p`` for the batch of parameters and its copies, ``4 N z`` for the contexts and
    features, and ``2 E p`` for the evaluation (N samples, E test contexts).
    """
    p, z, n, e = n_params, n_context_dims, config.samples, config.eval_contexts
    square = 6.0 * p * p if covariance else 0.0
    batch = 4.0 * n * p + 4.0 * n * (z + 1) + 2.0 * e * p
    if batch > square:
        name, value = "samples", n
    elif config.env_kwargs:
        name, value = "env_kwargs", config.env_kwargs
    else:
        name, value = "env", config.env
    what = f"the covariance (p x p, p = {p}) and the batch (samples x p)"
    check_fits_in_memory(8.0 * (square + batch), name, value, what)
