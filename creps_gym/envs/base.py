"""The one-step contextual episodic environment: the base every creps_gym env builds on.

An episode is one decision. ``reset`` draws (or is given) a context ``s``; the observation *is* the context.
``step(theta)`` evaluates the whole episode for the parameter vector ``theta`` and always returns
``terminated=True, truncated=False``. A return that is not finite (an objective that overflows for
finite parameters far outside the box) is refused with a ``ValueError`` naming the parameters
(:meth:`ContextualEpisodicEnv.check_returns`); no env returns ±inf or NaN.

Subclasses implement a single pure, batched function::

    evaluate(contexts (n, z), params (n, p)) -> (returns (n,), info {key: array (n, ...)})

which must be deterministic given its inputs. The scalar env calls it with ``n = 1`` and the native vector
env (:class:`ContextualEpisodicVectorEnv`) with the whole batch, so both give the same numbers.

Classes
-------
ContextualEpisodicEnv
    ``gymnasium.Env`` base class of the one-step envs.
ContextualEpisodicVectorEnv
    ``gymnasium.vector.VectorEnv`` that evaluates a batch with one ``evaluate`` call, with per-env contexts
    and the ``SAME_STEP`` and ``DISABLED`` autoreset modes.
SupportsRegret
    Protocol of envs whose optimum is known (``optimal_params`` and ``regret``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_fits_in_memory, check_in_box, check_positive_int
from creps_gym.envs.initial import box_initial_distribution, initial_distribution

__all__ = [
    "ContextualEpisodicEnv",
    "ContextualEpisodicVectorEnv",
    "SupportsRegret",
    "box_initial_distribution",
    "initial_distribution",
]

Array = NDArray[np.float64]
InfoBatch = dict[str, np.ndarray]


def _options_dict(options: Any) -> dict[str, Any]:
    """``reset``'s ``options`` as a new dict (None: empty), or a ``TypeError`` naming ``options``."""
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise TypeError(
            f"options: expected a dict such as {{'context': s}} or None, got {type(options).__name__}"
        )
    return dict(options)


@runtime_checkable
class SupportsRegret(Protocol):
    """An env whose optimal parameters are known, so the regret of any parameters can be computed."""

    def optimal_params(self, contexts: Array) -> Array:
        """theta*(s) for contexts of shape (n, z): shape (n, p)."""

    def regret(self, contexts: Array, params: Array) -> Array:
        """Regret (>= 0, 0 at the optimum) of params (n, p) under contexts (n, z): shape (n,)."""


class ContextualEpisodicEnv(gym.Env[Array, Array]):
    """Base class of the one-step contextual episodic environments.

    Subclasses call ``super().__init__`` with the context and parameter boxes and implement
    :meth:`evaluate`. They may override :meth:`sample_contexts` (default: uniform in the context box) and
    :meth:`reset_info` (extra keys for the reset ``info``).

    Parameters outside the action box are evaluated as given (the box describes the search region), unless
    the env's own manual says it clips them. Contexts given through ``reset(options={"context": s})`` must
    lie in the observation box.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": [], "render_fps": 4}

    def __init__(
        self,
        context_low: Array,
        context_high: Array,
        param_low: Array,
        param_high: Array,
        render_mode: str | None = None,
    ) -> None:
        self.observation_space = spaces.Box(
            np.asarray(context_low, dtype=np.float64),
            np.asarray(context_high, dtype=np.float64),
            dtype=np.float64,
        )
        self.action_space = spaces.Box(
            np.asarray(param_low, dtype=np.float64),
            np.asarray(param_high, dtype=np.float64),
            dtype=np.float64,
        )
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode: expected one of {self.metadata['render_modes']} or None, got {render_mode!r}"
            )
        self.render_mode = render_mode
        self._context: Array | None = None
        self._last_params: Array | None = None
        self._done = False

    # -- the model: subclasses implement these ---------------------------------------------------------
    @property
    def context_dim(self) -> int:
        """Number of context dimensions z."""
        return int(self.observation_space.shape[0])

    @property
    def param_dim(self) -> int:
        """Number of parameters p."""
        return int(self.action_space.shape[0])

    def evaluate(self, contexts: Array, params: Array) -> tuple[Array, InfoBatch]:
        """Evaluate a batch of episodes.

        Parameters
        ----------
        contexts : ndarray, shape (n, z)
        params : ndarray, shape (n, p)

        Returns
        -------
        returns : ndarray, shape (n,)
            Episodic returns (to be maximised).
        info : dict of str to ndarray
            Per-episode diagnostics, each with leading dimension n.
        """
        raise NotImplementedError

    def initial_distribution(self) -> tuple[Array, Array]:
        """Mean and standard deviations (p,) a search should start from (the env-declared default).

        Default: :func:`box_initial_distribution` (the box's centre and a quarter of its width). Envs with a
        better known start override it; the runner, the CLI and :func:`initial_distribution` use it when the
        user gives no initial mean or standard deviation.
        """
        return box_initial_distribution(self.action_space)

    def sample_contexts(self, rng: np.random.Generator, n: int) -> Array:
        """Draw ``n`` contexts, shape (n, z). Default: uniform in the observation box."""
        low, high = self.observation_space.low, self.observation_space.high
        return low + (high - low) * rng.random((n, low.shape[0]))  # the numbers of rng.uniform, faster

    def reset_info(self, contexts: Array) -> InfoBatch:
        """Extra reset-``info`` entries for contexts (n, z); each value has leading dimension n."""
        return {}

    # -- input checking shared with the vector env -----------------------------------------------------
    def check_contexts(self, contexts: Any, name: str = "options['context']") -> Array:
        """Validate contexts of shape (n, z) that must lie in the observation box."""
        contexts = as_float_array(contexts, name, (None, self.context_dim))
        check_in_box(contexts, self.observation_space.low, self.observation_space.high, name)
        return contexts

    def check_params(self, params: Any, name: str = "action") -> Array:
        """Validate a batch of finite parameter vectors, shape (n, p)."""
        return as_float_array(params, name, (None, self.param_dim))

    def check_returns(self, returns: Any, params: Array, name: str = "action") -> Array:
        """Validate the returns (n,) of :meth:`evaluate` for ``params`` (n, p): real and finite.

        Finite parameters far outside the box can overflow an objective (the Sphere at 1e200 gives -inf).
        That is refused with a ``ValueError`` naming the parameters, never passed on as a silent ±inf or
        NaN return: the policy of every creps_gym env.
        """
        owner = type(self).__name__
        returns = as_float_array(returns, f"{owner}.evaluate() returns", (params.shape[0],), finite=False)
        bad = np.flatnonzero(~np.isfinite(returns))
        if bad.size:
            row = int(bad[0])
            raise ValueError(
                f"{name}: expected a finite return, got {returns[row]} for params {params[row].tolist()} "
                f"(row {row}); {owner}'s objective is not finite there (e.g. it overflows far outside the "
                "parameter box)"
            )
        return returns

    # -- gymnasium API -----------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Array, dict]:
        """Start an episode. ``options={"context": s}`` sets the context (shape (z,)); else it is sampled."""
        options = _options_dict(options)
        unknown = set(options) - {"context"}
        if unknown:
            raise ValueError(f"options: expected only the key 'context', got unknown keys {sorted(unknown)}")
        given = None
        if "context" in options:  # validated before seeding, so a rejected reset changes nothing
            given = as_float_array(options["context"], "options['context']", (self.context_dim,))
            given = self.check_contexts(given[None, :])[0]
        super().reset(seed=seed)
        context = self.sample_contexts(self.np_random, 1)[0] if given is None else given
        self._context = context
        self._done = False
        self._last_params = None
        info = {"context": context.copy()}
        info.update({k: v[0] for k, v in self.reset_info(context[None, :]).items()})
        return context.copy(), info

    def step(self, action: Any) -> tuple[Array, float, bool, bool, dict]:
        """Run the whole episode with parameters ``action`` (shape (p,))."""
        if self._context is None:
            raise RuntimeError("step() called before reset(): call reset() to draw a context first")
        if self._done:
            raise RuntimeError(
                "step() called after the episode terminated: each episode is one step, call reset()"
            )
        params = as_float_array(action, "action", (self.param_dim,))[None, :]
        returns, batch_info = self.evaluate(self._context[None, :], params)
        returns = self.check_returns(returns, params)  # before any state changes
        self._done = True
        self._last_params = params[0].copy()
        info = {"context": self._context.copy()}
        info.update({k: v[0] for k, v in batch_info.items()})
        return self._context.copy(), float(returns[0]), True, False, info

    @property
    def context(self) -> Array | None:
        """The current episode's context, shape (z,), or None before the first reset."""
        return None if self._context is None else self._context.copy()


class ContextualEpisodicVectorEnv(VectorEnv):
    """Native vector env: the whole batch is evaluated with one call of the single env's ``evaluate``.

    Subclasses set ``single_env_class``; ``make_vec(id, num_envs=n)`` then builds one model instance with
    the registered kwargs.

    * ``reset(seed=..., options={"context": array (n, z)})`` sets per-env contexts; ``options["reset_mask"]``
      (bool, shape (n,)) resets only some envs, as in Gymnasium's ``DISABLED`` autoreset mode.
    * ``autoreset_mode=AutoresetMode.SAME_STEP`` (default): after each step every env is reset with a fresh
      context; the terminal context and info are in ``info["final_obs"]`` and ``info["final_info"]``.
    * ``autoreset_mode=AutoresetMode.DISABLED``: the user resets; stepping a finished env raises.
    """

    single_env_class: ClassVar[type[ContextualEpisodicEnv]]
    _MODES = (AutoresetMode.SAME_STEP, AutoresetMode.DISABLED)

    def __init__(
        self,
        num_envs: int,
        autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
        **env_kwargs: Any,
    ) -> None:
        self.num_envs = check_positive_int(num_envs, "num_envs")
        mode = next((m for m in self._MODES if autoreset_mode in (m, m.value)), None)
        if mode is None:
            raise ValueError(
                f"autoreset_mode: expected one of {[m.value for m in self._MODES]}, got {autoreset_mode!r}"
            )
        self.autoreset_mode = mode
        self.model = self.single_env_class(**env_kwargs)
        floats = 4 * (self.model.context_dim + self.model.param_dim) + 4  # per env: spaces, contexts, results
        check_fits_in_memory(8.0 * floats * self.num_envs, "num_envs", self.num_envs, "the batched arrays")
        self.metadata = {**self.model.metadata, "autoreset_mode": mode}
        self.render_mode = self.model.render_mode
        self.single_observation_space = self.model.observation_space
        self.single_action_space = self.model.action_space
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, self.num_envs)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, self.num_envs)
        self._contexts = np.zeros((self.num_envs, self.model.context_dim))
        self._active = np.zeros(self.num_envs, dtype=bool)
        self._np_random, self._np_random_seed = seeding.np_random(None)

    def _new_contexts(self, count: int) -> Array:
        return self.model.sample_contexts(self._np_random, count)

    def _reset_infos(self, contexts: Array, mask: NDArray[np.bool_]) -> dict:
        info: dict[str, Any] = {"context": contexts.copy(), "_context": mask.copy()}
        for key, value in self.model.reset_info(contexts).items():
            info[key], info["_" + key] = value, mask.copy()
        return info

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        """Reset all envs (or those in ``options["reset_mask"]``); returns contexts (n, z) and info."""
        if isinstance(seed, list):
            raise TypeError("seed: expected an int or None for a native vector env, got a list")
        options = _options_dict(options)
        unknown = set(options) - {"context", "reset_mask"}
        if unknown:
            raise ValueError(
                f"options: expected keys 'context' and 'reset_mask', got unknown keys {sorted(unknown)}"
            )
        mask = np.ones(self.num_envs, dtype=bool)
        if "reset_mask" in options:
            mask = np.asarray(options["reset_mask"])
            if mask.dtype != np.bool_ or mask.shape != (self.num_envs,):
                raise ValueError(
                    f"options['reset_mask']: expected a bool array of shape ({self.num_envs},), "
                    f"got dtype {mask.dtype} and shape {mask.shape}"
                )
        count = int(mask.sum())
        if "context" in options:
            given = as_float_array(options["context"], "options['context']")
            if given.ndim == 1:
                given = np.broadcast_to(given, (count, given.shape[0]))
            contexts = self.model.check_contexts(given)
            if contexts.shape[0] != count:
                raise ValueError(
                    f"options['context']: expected shape ({count}, {self.model.context_dim}) for the envs "
                    f"being reset, got {contexts.shape}"
                )
        if seed is not None:  # after validation, so a rejected reset changes nothing
            self._np_random, self._np_random_seed = seeding.np_random(seed)
        if "context" not in options:
            contexts = self._new_contexts(count)
        self._contexts[mask] = contexts
        self._active[mask] = True
        return self._contexts.copy(), self._reset_infos(self._contexts, mask)

    def step(self, actions: Any):
        """Evaluate all envs at once; returns (obs, rewards, terminations, truncations, info)."""
        if not self._active.all():
            idle = np.flatnonzero(~self._active).tolist()
            raise RuntimeError(
                f"step() called with envs {idle} not reset since their episode ended (autoreset_mode="
                f"{self.autoreset_mode.value}): call reset() (with options['reset_mask'] for some envs)"
            )
        params = self.model.check_params(actions, "actions")
        if params.shape[0] != self.num_envs:
            raise ValueError(
                f"actions: expected shape ({self.num_envs}, {self.model.param_dim}), got {params.shape}"
            )
        returns, batch_info = self.model.evaluate(self._contexts, params)
        returns = self.model.check_returns(returns, params, "actions")
        ones = np.ones(self.num_envs, dtype=bool)
        step_info: dict[str, Any] = {"context": self._contexts.copy(), "_context": ones.copy()}
        for key, value in batch_info.items():
            step_info[key], step_info["_" + key] = value, ones.copy()
        terminated = np.ones(self.num_envs, dtype=bool)
        truncated = np.zeros(self.num_envs, dtype=bool)
        final_obs = self._contexts.copy()
        self._active[:] = False
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            self._contexts = self._new_contexts(self.num_envs)
            self._active[:] = True
            info = self._reset_infos(self._contexts, ones)
            info.update({"final_obs": final_obs, "_final_obs": ones.copy(), "final_info": step_info})
            info["_final_info"] = ones.copy()
            return self._contexts.copy(), returns, terminated, truncated, info
        return final_obs, returns, terminated, truncated, step_info
