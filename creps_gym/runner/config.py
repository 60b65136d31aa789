"""The resolved configuration of a run (:class:`RunConfig`), its validation and its JSON form."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np

from creps_gym._validation import check_positive_int, config_field
from creps_gym.errors import ConfigError, ConfigTypeError

__all__ = [
    "BACKENDS",
    "CONTEXT_DRAWS",
    "MAKE_ARGUMENTS",
    "RUN_OWNED_OPTIONS",
    "VECTOR_MODES",
    "RunConfig",
    "check_ray_address",
]

BACKENDS = ("auto", "serial", "vector", "ray")
CONTEXT_DRAWS = ("batch", "reset")
VECTOR_MODES = ("auto", "native", "sync", "async")

#: ``gymnasium.make``'s own keyword arguments: never env keyword arguments (``make_vec`` and the native
#: vector env would pass them to the env, which does not take them).
MAKE_ARGUMENTS = ("max_episode_steps", "autoreset", "apply_api_compatibility", "disable_env_checker")


def _optional_positive(value: Any, name: str, *, integer: bool) -> Any:
    if value is None:
        return None
    if integer:
        return check_positive_int(value, name)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < math.inf:
        raise ValueError(f"{name}: expected a positive finite number or None, got {value!r}")
    return float(value)


_HOST_PORT = re.compile(r"(?:[A-Za-z0-9._-]+|\[[0-9A-Fa-f:.]+\]):[0-9]{1,5}")


def check_ray_address(value: Any, name: str = "ray_address") -> str:
    """``value`` if it is ``"auto"`` or ``"HOST:PORT"`` (the address ``ray start --head`` prints).

    Raises ``TypeError`` for a non-str and ``ValueError`` for anything else (Ray Client's ``ray://``
    addresses included), naming ``name``.
    """
    if not isinstance(value, str):
        raise TypeError(f"{name}: expected a str 'HOST:PORT' or 'auto', got {type(value).__name__} {value!r}")
    if value != "auto" and not (_HOST_PORT.fullmatch(value) and 0 < int(value.rpartition(":")[2]) < 65536):
        raise ValueError(
            f"{name}: expected 'HOST:PORT' (the address `ray start --head` prints, e.g. '10.0.0.1:6379') "
            f"or 'auto', got {value!r}"
        )
    return value


def _vector_or_scalar(value: Any, name: str, positive: bool) -> Any:
    """A finite number or a list of them (numpy scalars and 1-D arrays accepted) as float or list of float.

    ``positive``: standard deviations, which must be > 0 with a finite variance > 0 (their square).
    """
    if value is None:
        return None
    if isinstance(value, np.ndarray):
        if value.ndim > 1:
            raise ValueError(f"{name}: expected a number or a 1-D list of numbers, got shape {value.shape}")
        value = value.tolist()
    items = value if isinstance(value, (list, tuple)) else [value]
    for item in items:
        real = isinstance(item, (int, float, np.integer, np.floating)) and not isinstance(item, bool)
        bad = not real or not math.isfinite(item)
        if not bad and positive:
            bad = not (item > 0 and 0.0 < float(item) * float(item) < math.inf)
        if bad:
            kind = "positive finite numbers with a finite variance > 0" if positive else "finite numbers"
            raise ValueError(f"{name}: expected a number or a list of {kind}, got {value!r}")
    return [float(v) for v in items] if isinstance(value, (list, tuple)) else float(value)


#: The smallest value of each integer field (``samples``: when given).
_MINIMA = {
    "iterations": 1,
    "samples": 2,
    "seed": 0,
    "eval_every": 1,
    "eval_contexts": 1,
    "retries": 0,
    "checkpoint_every": 1,
}

#: Optimiser keywords that the run sets itself, and the run option (and flag) to use instead.
RUN_OWNED_OPTIONS = {
    "initial_mean": "--initial-mean (initial_mean= in Python)",
    "initial_cov": "--initial-std (initial_std= in Python; initial_cov = initial_std²)",
    "seed": "--seed (seed= in Python; the optimiser's seed is derived from it)",
}


def _check_run_owned_options(options: Mapping[str, Any]) -> None:
    """Refuse an optimiser option that the run passes itself (a raw "multiple values" TypeError else)."""
    for key, advice in RUN_OWNED_OPTIONS.items():
        if key in options:
            raise ConfigError(
                "optimizer_options",
                f"expected no {key!r}, which the run sets: use {advice}; got {key}={options[key]!r}",
            )


@dataclass(frozen=True)
class RunConfig:
    """Everything that defines a run; validates itself. Written to ``config.json`` in the run directory.

    Parameters
    ----------
    env : str or None
        Registered env id (None when the env object was given directly; such runs resume only when the
        same env is passed to :func:`~creps_gym.runner.resume`).
    optimizer : str or None
        Registry name (None when an optimiser object was given).
    iterations : int
        Maximum number of iterations (ask, evaluate, tell).
    samples : int
        Episodes per iteration (>= 2).
    seed : int
        Master seed (>= 0), split into env, optimiser and evaluation streams.
    env_kwargs, optimizer_options : dict
        Keyword arguments of ``gymnasium.make`` and of the optimiser.
    eval_every : int
        Evaluate the recommended policy every this many iterations (and at the last one).
    eval_contexts : int
        Size of the fixed, seeded set of test contexts.
    context_draws : {"batch", "reset"}
        How an iteration's contexts are drawn (see :mod:`creps_gym.runner.contexts`): one batched draw
        where the env allows it, or one seeded ``env.reset`` per episode (the stream of run directories of
        format ``creps_gym.run/2``, whose ``config.json`` has no such field and which resume with it).
    backend : {"auto", "serial", "vector", "ray"}
        Where episodes run (see :mod:`creps_gym.runner.backends`); ``"auto"`` is the native vector env of
        a registered id that has one, else ``"serial"``.
    workers : int or None
        Vector: sub-envs (default: samples for the native vector env, else the CPU count); Ray: tasks per
        iteration (default: the cluster's CPUs).
    vector_mode : {"auto", "native", "sync", "async"}
        Vector backend flavour; ``auto`` is the native vector env where registered, else ``async``.
    retries : int
        How many times a failed episode (or a dead Ray worker's task) is re-run before the run stops.
    max_episodes : int or None
        Episode budget: stop before an iteration would exceed it.
    target_regret : float or None
        Stop once the evaluated mean regret is at most this (envs with a regret only).
    max_time : float or None
        Stop after this many seconds of wall time.
    checkpoint_every : int
        Checkpoint every this many iterations (and at the end), when the run has a directory.
    initial_mean, initial_std : float, list of float or None
        Initial search distribution; None = the env-declared one
        (:func:`~creps_gym.envs.base.initial_distribution`: an env's own start, else the action box's centre
        and a quarter of its width).
        ``initial_mean="uniform"`` draws the mean uniformly in the action box from the master seed (the
        paper's initialisation), from its own ``SeedSequence`` child
        (:class:`~creps_gym.runner.seeds.SeedPlan`).
    ray_address : str or None
        ``backend="ray"`` only: join the running Ray cluster at ``"HOST:PORT"`` (or ``"auto"``, the
        cluster last started on this machine) and leave it running. None: the ``RAY_ADDRESS`` environment
        variable's cluster if set, else a local Ray started and stopped by the run (see
        :mod:`creps_gym.runner.backends.ray`). Not part of the run's identity: a resumed run never joins
        the address its ``config.json`` records.
    context_selector : str or None
        A registered context selector (:func:`creps_gym.selectors.selector_names`) that chooses the
        training contexts instead of the env's sampler (``context_draws="batch"`` only; see
        ``docs/contexts.md``). None: the env's own draws (or a selector object given to the runner).
    context_selector_options : dict
        The selector's keyword arguments, as JSON data.
    divergence : float or None
        Stop with the reason ``"divergence"`` once 10 consecutive evaluations are worse than the first by
        more than this factor times its magnitude (:mod:`creps_gym.runner.divergence`); None: never.
    """

    env: str | None
    optimizer: str | None
    iterations: int
    samples: int | None
    seed: int
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    optimizer_options: dict[str, Any] = field(default_factory=dict)
    eval_every: int = 1
    eval_contexts: int = 16
    context_draws: str = "batch"
    backend: str = "auto"
    workers: int | None = None
    vector_mode: str = "auto"
    retries: int = 2
    max_episodes: int | None = None
    target_regret: float | None = None
    max_time: float | None = None
    checkpoint_every: int = 10
    initial_mean: Any = None
    initial_std: Any = None
    ray_address: str | None = None
    context_selector: str | None = None
    context_selector_options: dict[str, Any] = field(default_factory=dict)
    divergence: float | None = 1000.0

    def __post_init__(self) -> None:
        for name in ("env", "optimizer"):
            value = getattr(self, name)
            if value is not None and (not isinstance(value, str) or not value):
                raise ConfigTypeError(name, f"expected a non-empty str or None, got {value!r}")
        for name, minimum in _MINIMA.items():
            if name != "samples" or self.samples is not None:  # None: the optimiser's recommended batch size
                with config_field(name):
                    check_positive_int(getattr(self, name), name, minimum=minimum)
        self._check_options()
        self._check_backend()
        self._check_selector()
        for name in ("workers", "max_episodes"):
            with config_field(name):
                _optional_positive(getattr(self, name), name, integer=True)
        for name in ("target_regret", "max_time", "divergence"):
            with config_field(name):
                object.__setattr__(self, name, _optional_positive(getattr(self, name), name, integer=False))
        with config_field("initial_mean"):
            if not (isinstance(self.initial_mean, str) and self.initial_mean == "uniform"):
                object.__setattr__(
                    self, "initial_mean", _vector_or_scalar(self.initial_mean, "initial_mean", False)
                )
        with config_field("initial_std"):
            object.__setattr__(self, "initial_std", _vector_or_scalar(self.initial_std, "initial_std", True))
        if self.max_episodes is not None and self.samples and self.max_episodes < self.samples:
            raise ConfigError(
                "max_episodes",
                f"expected at least one iteration's samples ({self.samples}), got {self.max_episodes}",
            )

    def _check_options(self) -> None:
        for name in ("env_kwargs", "optimizer_options"):
            if not isinstance(getattr(self, name), Mapping):
                raise ConfigTypeError(name, f"expected a dict, got {type(getattr(self, name)).__name__}")
            object.__setattr__(self, name, dict(getattr(self, name)))
        _check_run_owned_options(self.optimizer_options)
        taken = sorted(set(self.env_kwargs) & set(MAKE_ARGUMENTS))
        if taken:
            raise ConfigError(
                "env_kwargs",
                f"expected keyword arguments of the env, got {taken[0]!r} (an argument of "
                "gymnasium.make itself, which the runner sets; the vector backends would pass it to the env)",
            )

    def _check_backend(self) -> None:
        if self.backend not in BACKENDS:
            raise ConfigError("backend", f"expected one of {list(BACKENDS)}, got {self.backend!r}")
        if self.context_draws not in CONTEXT_DRAWS:
            raise ConfigError(
                "context_draws", f"expected one of {list(CONTEXT_DRAWS)}, got {self.context_draws!r}"
            )
        if self.vector_mode not in VECTOR_MODES:
            raise ConfigError(
                "vector_mode", f"expected one of {list(VECTOR_MODES)}, got {self.vector_mode!r}"
            )
        if self.ray_address is not None:
            with config_field("ray_address"):
                check_ray_address(self.ray_address)
            if self.backend != "ray":
                raise ConfigError(
                    "ray_address",
                    f"expected None unless backend='ray' (backend is {self.backend!r}), "
                    f"got {self.ray_address!r}",
                )

    def _check_selector(self) -> None:
        if self.context_selector is None:
            if self.context_selector_options:
                raise ConfigError(
                    "context_selector_options",
                    f"expected none without a context_selector, got {self.context_selector_options!r}",
                )
            object.__setattr__(self, "context_selector_options", dict(self.context_selector_options))
            return
        from creps_gym.selectors.registry import check_options

        options = check_options(self.context_selector, self.context_selector_options)  # its ConfigErrors
        object.__setattr__(self, "context_selector_options", options)
        if self.context_draws != "batch":
            raise ConfigError(
                "context_draws",
                "expected 'batch' with a context_selector (it sets every context), "
                f"got {self.context_draws!r}",
            )

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable dict."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RunConfig:
        """Inverse of :meth:`to_dict`; unknown keys raise ``ValueError``."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"config: expected keys from {sorted(known)}, got unknown keys {unknown}")
        return cls(**dict(data))
