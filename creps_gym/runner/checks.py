"""Checks the runner makes before a run starts, so that bad set-ups fail at once with a clear error.

* :func:`check_optimizer`: an optimiser object follows the ask/tell protocol of
  :class:`creps_gym.optimizers.AskTellOptimizer`; raw pycma, nevergrad and optuna objects are refused
  with the adapter to use.
* :func:`check_minimum_batch`: the batch is at least the optimiser's minimum workable size
  (:func:`creps_gym.optimizers.registry.minimum_samples`; measured in ``docs/optimizers.md``).
* :func:`check_batch_size`: one ask/tell of a fresh copy of a named optimiser on a synthetic batch of
  the run's size, so options that only fail at the first ``tell`` (``epsilon >= log N``, a batch too
  small for the features) fail before anything is written.
* :func:`unwrapped_model`: the creps_gym model behind an env, when the wrappers around it change nothing
  the evaluation computes (so the runner may evaluate the model's batched ``evaluate`` directly).
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import (
    ConfigError,
    ConfigTypeError,
    as_float_array,
    check_generator_state,
    config_field,
)
from creps_gym.envs.evaluation import contextual_model
from creps_gym.optimizers.registry import minimum_samples
from creps_gym.wrappers import FixedContexts, SampleContexts

__all__ = [
    "CRITERION",
    "MODEL_PRESERVING_WRAPPERS",
    "check_batch_size",
    "check_box_spaces",
    "check_minimum_batch",
    "check_optimizer",
    "check_optimizer_sizes",
    "check_ray_cluster",
    "generator_state",
    "real_params",
    "stop_criteria",
    "unwrapped_model",
]

PROTOCOL_METHODS = ("ask", "tell", "recommend", "stop", "state_dict")
_ADAPTERS = {
    "cma": "creps_gym.optimizers.adapters.pycma.CMAAdapter (registry name 'cma')",
    "nevergrad": "creps_gym.optimizers.adapters.nevergrad.NevergradAdapter (registry name 'nevergrad')",
    "optuna": "creps_gym.optimizers.adapters.optuna.OptunaAdapter (registry name 'optuna')",
}

#: A stop criterion's name, as ``stop()`` may report it (pycma's ``tolfun``, ``max_std_growth``, ...):
#: letters, digits, ``_``, ``.``, ``+`` and ``-``, so that a stop reason is plain text wherever it is shown.
CRITERION = re.compile(r"[\w.+-]{1,100}")

# Wrappers that change neither the observation, the action nor the reward of a one-step episode.
MODEL_PRESERVING_WRAPPERS: tuple[type, ...] = (
    gym.wrappers.OrderEnforcing,
    gym.wrappers.PassiveEnvChecker,
    gym.wrappers.TimeLimit,
    FixedContexts,  # they choose the training contexts; the test contexts come from the model
    SampleContexts,
)


def check_optimizer(optimizer: Any) -> None:
    """Raise TypeError unless ``optimizer`` is an ask/tell optimiser object of this package's protocol.

    The protocol: methods ``ask``, ``tell``, ``recommend``, ``stop``, ``state_dict`` and a ``diagnostics``
    attribute. Objects of pycma, nevergrad or optuna follow their own libraries' protocols: the error
    names the adapter that wraps them.
    """
    cls = optimizer if isinstance(optimizer, type) else type(optimizer)
    name = f"{cls.__module__}.{cls.__qualname__}"
    adapter = _ADAPTERS.get(cls.__module__.split(".")[0])
    if adapter is not None:
        raise TypeError(
            f"optimizer: expected a creps_gym ask/tell optimiser or a registry name, got a raw {name}; "
            f"use the adapter {adapter}"
        )
    if isinstance(optimizer, type):
        raise TypeError(f"optimizer: expected an optimiser object or a registry name, got the class {name}")
    missing = [method for method in PROTOCOL_METHODS if not callable(getattr(cls, method, None))]
    if not (hasattr(cls, "diagnostics") or "diagnostics" in getattr(optimizer, "__dict__", {})):
        missing.append("diagnostics")
    if missing:
        raise TypeError(
            "optimizer: expected an ask/tell optimiser (methods ask, tell, recommend, stop, state_dict and "
            "a diagnostics property, see creps_gym.optimizers.AskTellOptimizer) or a registry name, got "
            f"{name} without {', '.join(missing)}"
        )


def check_minimum_batch(optimizer: Any, runner: Any) -> None:
    """ValueError naming ``samples`` when the runner's batch is below the optimiser's minimum batch size.

    ``runner`` has the ``config``, ``n_params`` and ``n_context_dims`` of the run. The minimum is the
    class's ``minimum_batch_size(n_params, n_context_dims)`` (every native optimiser has one); optimisers
    without one (adapters, users' classes) are not checked.
    """
    config, p, z = runner.config, runner.n_params, runner.n_context_dims
    smallest = minimum_samples(optimizer, p, z)
    if smallest is not None and config.samples < smallest:
        label = repr(config.optimizer) if config.optimizer else type(optimizer).__name__
        raise ConfigError(
            "samples",
            f"expected at least {smallest} episodes per iteration for {label} with {p} parameters and {z} "
            f"context dimension(s) (smaller batches diverge; see docs/optimizers.md, 'Batch size'), got "
            f"{config.samples}",
        )


def check_optimizer_sizes(optimizer: Any, name: str, runner: Any) -> None:
    """ValueError naming ``name`` unless the optimiser's ``n_params`` and ``n_context_dims`` are the
    runner's (``runner.env_name`` names the env)."""
    for attribute in ("n_params", "n_context_dims"):
        expected = getattr(runner, attribute)
        got = getattr(optimizer, attribute, expected)
        if got != expected:
            raise ConfigError(name, f"expected {attribute} = {expected} for {runner.env_name}, got {got}")


def check_batch_size(
    make: Callable[[], Any], contexts: NDArray[np.float64], options: Mapping[str, Any], label: str
) -> None:
    """One ask/tell of ``make()`` on ``contexts`` (n, z) with distinct returns; ValueError if it refuses.

    An error naming one of the optimiser ``options`` (e.g. ``epsilon``) is raised as it is. Any other
    ``ValueError`` of the ``tell`` is an error of ``samples`` if a batch four times as large is accepted,
    else of the initial distribution. Other exceptions are left to the run itself (the synthetic batch is not
    the run's).
    """
    error = _tell_error(make, contexts)
    if error is None:
        return
    if str(error).partition(":")[0] in options:
        raise ConfigError("optimizer_options", str(error), str(error)) from None
    if _tell_error(make, np.tile(contexts, (4, 1))) is None:
        raise ConfigError(
            "samples", f"expected a batch size that {label} can learn from, got {contexts.shape[0]} ({error})"
        ) from None
    raise ValueError(
        f"initial_mean, initial_std: expected a start {label} can learn from (a synthetic batch drawn there "
        f"failed at any batch size), got this error: {error}"
    ) from None


def _tell_error(make: Callable[[], Any], contexts: NDArray[np.float64]) -> ValueError | None:
    """The ``ValueError`` one ask/tell of a fresh ``make()`` on ``contexts`` raises, if any."""
    optimizer = make()
    params = optimizer.ask(contexts)
    try:
        optimizer.tell(contexts, params, -np.arange(contexts.shape[0], dtype=np.float64))
    except ValueError as exc:
        return exc
    except Exception:  # only the batch size is checked here; the run reports any other failure
        return None
    return None


def check_box_spaces(env: gym.Env) -> None:
    """``TypeError`` unless the env's observation and action spaces are Boxes (contexts and θ)."""
    for name in ("observation_space", "action_space"):
        space = getattr(env, name)
        if not isinstance(space, gym.spaces.Box):
            raise ConfigTypeError("env", f"expected a Box {name} (contexts and parameters θ), got {space}")


def check_ray_cluster(config: Any) -> None:
    """For the Ray backend: ``ImportError`` without Ray, and, joining a cluster, ``ValueError`` naming the
    address unless Ray answers there.

    Called before a new run directory is created, so a wrong address leaves nothing behind.
    """
    if config.backend != "ray":
        return
    from creps_gym.optimizers.adapters.base import import_optional
    from creps_gym.runner.ray_backend import check_reachable, resolve_address

    import_optional("ray", "ray")  # a missing Ray (exit 4) leaves no run folder behind either

    address, origin = resolve_address(config.ray_address, os.environ)
    if address is not None and address != "auto":
        with config_field("ray_address" if origin == "ray_address" else None):
            check_reachable(address, origin)


def generator_state(state: Any) -> Any:
    """``state`` if it is a PCG64 state a Generator can have written, else ``ValueError``.

    Checked here because numpy itself differs: recent versions raise ``OverflowError`` for a state outside
    [0, 2**128), older ones (1.23) take ``-1`` silently as another state.
    """
    return check_generator_state(state, "env_rng")


def real_params(value: Any, method: str, shape: tuple[int, int] | None = None) -> NDArray[np.float64]:
    """The output of an optimiser's ``ask`` or ``recommend`` as float64, never converted from complex.

    ``TypeError`` naming ``method`` for complex, boolean, string or object output (numpy would drop an
    imaginary part with only a warning); with ``shape`` (n, p), a ``ValueError`` naming ``method`` for
    another shape (an ``ask`` that returns n - 1 rows), before any episode runs. The values are checked
    where they are used.
    """
    return as_float_array(value, f"optimizer.{method}() output", shape, finite=False)


def stop_criteria(met: Any) -> list[str]:
    """The names of the criteria an optimiser's ``stop()`` reports as met, sorted (empty: go on).

    The protocol: a dict (or another mapping) whose keys are the names of the met criteria. A ``str``
    (whose letters would be read as names), a non-mapping or a name that is not a short plain word
    (:data:`CRITERION`) raises ``TypeError`` or ``ValueError`` naming ``stop()``.
    """
    if not isinstance(met, Mapping):
        raise TypeError(
            "optimizer.stop(): expected a dict of the met stop criteria (names as keys, empty to go on), "
            f"got {type(met).__name__} {str(met)[:80]!r}"
        )
    for name in met:
        if not isinstance(name, str):
            raise TypeError(
                f"optimizer.stop(): expected str criterion names, got {type(name).__name__} {name!r}"
            )
        if not CRITERION.fullmatch(name):
            raise ValueError(
                "optimizer.stop(): expected criterion names of letters, digits, '_', '.', '+' or '-' (at "
                f"most 100), got {name[:120]!r}"
            )
    return sorted(met)


def unwrapped_model(env: gym.Env) -> Any:
    """The creps_gym model behind ``env`` if every wrapper around it is in ``MODEL_PRESERVING_WRAPPERS``.

    None otherwise (an env that is not a creps_gym model, or a wrapper that may change the reward, the
    observation or the action, e.g. ``TransformReward`` or ``NormalizeParams``): then the runner evaluates
    through episodes of the env itself, which see what training sees.
    """
    try:
        model = contextual_model(env)
    except TypeError:
        return None
    layer = env
    while layer is not model:
        if not isinstance(layer, MODEL_PRESERVING_WRAPPERS):
            return None
        layer = layer.env
    return model
