"""What a run builds from its configuration: the optimiser, its initial search distribution, the backend.

Used by :class:`~creps_gym.runner.loop.Runner`; a resumed run restores its optimiser from the checkpoint
instead and builds only the backend.
"""

from __future__ import annotations

import inspect
import math
import re
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from creps_gym._validation import config_field
from creps_gym.envs.base import box_initial_distribution, initial_distribution
from creps_gym.errors import ConfigError, ConfigTypeError
from creps_gym.optimizers.registry import make_optimizer
from creps_gym.optimizers.registry import optimizer_class as registered_class
from creps_gym.runner.backends import Backend, EnvSource, make_backend
from creps_gym.runner.config import RunConfig
from creps_gym.runner.seeds import SeedPlan, seed_child

__all__ = [
    "build_backend",
    "build_optimizer",
    "default_initial_distribution",
    "make_env",
    "per_parameter",
    "uniform_mean",
]

Array = NDArray[np.float64]


def make_env(env_id: str, kwargs: dict[str, Any]) -> gym.Env:
    """``gymnasium.make(env_id, **kwargs)``, with the env's own message for a bad keyword argument.

    An unknown keyword raises ``TypeError`` naming the keywords the env takes (and the closest ones); an
    error the env itself raises (``dim: expected ...``) is raised as it is, without Gymnasium's suffix ("was
    raised from the environment creator ... with kwargs (...)"), which repeats every default.
    """
    try:
        return gym.make(env_id, **kwargs)
    except TypeError as exc:
        message, suffix, _ = str(exc).partition(" was raised from the environment creator")
        if not suffix:
            raise
        unknown = re.search(r"(\w+)\.__init__\(\) got an unexpected keyword argument '(\w+)'", message)
        if unknown is not None and unknown.group(2) in kwargs:
            reason = _unknown_keyword(env_id, unknown.group(2), unknown.group(1))
            raise ConfigTypeError("env_kwargs", reason) from None
        original = exc.__cause__ or exc.__context__  # the env's own error, e.g. "dim: expected an integer"
        if isinstance(original, TypeError):
            raise original from None
        raise


def _unknown_keyword(env_id: str, key: str, refused_by: str) -> str:
    """The message for an unknown env keyword: the keywords of the creator and of the class (in its
    MRO) that refused ``key``, with the closest ones."""
    from creps_gym._suggest import did_you_mean

    creator = gym.spec(env_id).entry_point
    if isinstance(creator, str):
        creator = gym.envs.registration.load_env_creator(creator)
    callables = [creator]
    callables += [cls.__init__ for cls in getattr(creator, "__mro__", ()) if cls.__name__ == refused_by]
    plain = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    valid: set[str] = set(gym.spec(env_id).kwargs)
    for function in callables:
        try:
            parameters = inspect.signature(function).parameters.values()
        except (TypeError, ValueError):  # no signature to read
            continue
        valid |= {p.name for p in parameters if p.kind in plain}
    names = sorted(valid - {"self", "render_mode"})
    return f"expected keywords of {env_id} from {names}, got {key!r}{did_you_mean(key, names)}"


def default_initial_distribution(action_space: gym.spaces.Box) -> tuple[Array, Array]:
    """Mean and standard deviations (p,) of the box rule, the runner's start for an env that declares none.

    The centre of the action box and a quarter of its width per coordinate (so mean ± 2 std spans the box);
    coordinates with an infinite bound get mean 0 and standard deviation 1. The runner starts from
    :func:`~creps_gym.envs.base.initial_distribution`, the env-declared distribution, which is this rule
    for envs without a declaration.
    """
    return box_initial_distribution(action_space)


def uniform_mean(action_space: gym.spaces.Box, seed: int) -> Array:
    """The paper's initialisation: a mean drawn uniformly in the action box from the master ``seed``."""
    low, high = action_space.low, action_space.high
    if not (np.isfinite(low).all() and np.isfinite(high).all()):
        raise ConfigError("initial_mean", "expected a number for an unbounded action box, got 'uniform'")
    return np.random.default_rng(seed_child(seed, SeedPlan.INITIAL_MEAN)).uniform(low, high)


def per_parameter(given: Any, name: str, default: Array, n_params: int) -> Array:
    """``given`` (a number or one per parameter) as shape (p,), or ``default`` if None or a string."""
    if given is None or isinstance(given, str):
        return default
    values = np.atleast_1d(np.asarray(given, np.float64))
    if values.shape not in ((1,), (n_params,)):
        raise ConfigError(
            name, f"expected a number or {n_params} numbers (one per parameter), got {values.shape[0]}"
        )
    return np.broadcast_to(values, (n_params,)).copy()


def build_optimizer(config: RunConfig, env: gym.Env, n_context_dims: int, seed: int) -> Any:
    """The registered optimiser ``config.optimizer`` with the run's initial distribution and ``seed``.

    The initial distribution is the env-declared one (:func:`creps_gym.envs.base.initial_distribution`)
    unless the config sets ``initial_mean`` (a number, one per parameter, or ``"uniform"``) or
    ``initial_std``. A budget option the optimiser's class names (``budget_option``) is set to the run's
    episode budget unless given; an option that grows the batch after a restart (``batch_growth_option``,
    C-CMA-ES's C13) must stay 1, since every iteration asks ``samples`` episodes.
    """
    n_params = int(np.prod(env.action_space.shape))
    mean, std = initial_distribution(env)  # the env-declared start (box rule for foreign envs)
    if isinstance(config.initial_mean, str) and config.initial_mean == "uniform":
        mean = uniform_mean(env.action_space, config.seed)
    else:
        mean = per_parameter(config.initial_mean, "initial_mean", mean, n_params)
    std = per_parameter(config.initial_std, "initial_std", std, n_params)
    with np.errstate(over="ignore", under="ignore"):
        variances = std**2
    if not (np.isfinite(variances).all() and (variances > 0).all()):  # e.g. an env-declared std of 1e200
        raise ConfigError("initial_std", f"expected standard deviations with finite variances > 0, got {std}")
    options = dict(config.optimizer_options)
    cls = registered_class(config.optimizer)
    budget_option = getattr(cls, "budget_option", None)
    if budget_option is not None and budget_option not in options:  # e.g. nevergrad's NGOpt needs it
        options[budget_option] = min(config.iterations * config.samples, config.max_episodes or math.inf)
    growth = getattr(cls, "batch_growth_option", None)  # the runner's batch is fixed: samples
    if growth is not None and options.get(growth, 1) != 1:
        reason = f"expected {growth}=1 (the runner's batch stays samples), got {options[growth]!r}"
        raise ConfigError("optimizer_options", reason)
    with config_field("optimizer_options" if config.optimizer_options else None):  # its error about one
        return make_optimizer(
            config.optimizer,
            n_params,
            n_context_dims,
            seed,
            initial_mean=mean,
            initial_cov=variances,
            **options,
        )


def build_backend(config: RunConfig, source: EnvSource, env: gym.Env | None = None) -> Backend:
    """The backend ``config`` names, running episodes of ``source`` (``env``: the env object, if any)."""
    return make_backend(
        config.backend,
        source,
        retries=config.retries,
        workers=config.workers,
        vector_mode=config.vector_mode,
        samples=config.samples,
        env=env,
        ray_address=config.ray_address,
    )
