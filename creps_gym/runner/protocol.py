"""The ask/tell protocol as the runner checks an optimiser against it: before a run starts, so that bad
set-ups fail at once with a clear error, and at each call.

* :func:`check_optimizer`: an optimiser object follows the ask/tell protocol of
  :class:`creps_gym.optimizers.AskTellOptimizer`; raw pycma, nevergrad and optuna objects are refused
  with the adapter to use.
* :func:`check_minimum_batch`: the batch is at least the optimiser's minimum workable size
  (:func:`creps_gym.optimizers.registry.minimum_samples`; measured in ``docs/optimizers.md``).
* :func:`check_batch_size`: one ask/tell of a fresh copy of a named optimiser on a synthetic batch of
  the run's size, so options that only fail at the first ``tell`` (``epsilon >= log N``, a batch too
  small for the features) fail before anything is written.
* :func:`real_params`, :func:`stop_criteria`: what an optimiser's ``ask``/``recommend`` and ``stop``
  return, checked at each iteration; :func:`generator_state`: a checkpointed generator state.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_generator_state
from creps_gym.errors import ConfigError
from creps_gym.optimizers.registry import minimum_samples

__all__ = [
    "CRITERION",
    "check_batch_size",
    "check_minimum_batch",
    "check_optimizer",
    "check_optimizer_sizes",
    "generator_state",
    "real_params",
    "stop_criteria",
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

    An optimiser's :class:`~creps_gym.errors.ConfigError` whose ``field`` is one of its ``options`` (e.g.
    ``epsilon``) is raised as an error of ``optimizer_options`` with its message. Any other
    ``ValueError`` of the ``tell`` is an error of ``samples`` if a batch four times as large is accepted,
    else of the initial distribution. Other exceptions are left to the run itself (the synthetic batch is not
    the run's).
    """
    error = _tell_error(make, contexts)
    if error is None:
        return
    if getattr(error, "field", None) in options:  # the optimiser's ConfigError about one of its options
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
