"""Episodic conversion: a step-based Gymnasium task plus a parametric controller as a one-step contextual env.

``EpisodicEnv(inner, controller, context)`` is a :class:`~creps_gym.envs.base.ContextualEpisodicEnv`:

* ``reset()`` yields the context, *taken from the inner env*: the inner env is reset with a seed drawn from
  the episodic env's ``np_random`` and the accessor reads its task (a goal env's desired goal, Reacher's
  target). ``reset(options={"context": s})`` sets it instead.
* ``step(θ)`` runs the whole inner episode: the inner env is reset (always with ``start_seed``), the
  context is imposed, and the controller acts with θ until the inner episode terminates or is truncated.
  The reward is the sum of the inner rewards (the episodic return).
* ``info`` holds ``"inner_length"`` (steps), ``"inner_terminated"``, ``"inner_truncated"`` and
  ``"inner_info"`` (the final inner step's info dict), besides ``"context"``.

Design. Subclassing :class:`ContextualEpisodicEnv` (rather than writing a plain ``gymnasium.Env``) gives the
project's conventions for free: float64 boxes, ``reset(options={"context": s})`` with box checks, one-step
episodes with clear errors, a native vector version (:class:`EpisodicVectorEnv`) and every context wrapper.
It needs ``evaluate(contexts, params)`` to be a pure function; it is, because every inner episode starts
from the same inner reset (``start_seed``) and only the context and θ differ. The return is then a
deterministic function of (s, θ), the model CREPS assumes, and candidates are compared under common random
numbers. ``evaluate`` loops over the batch on one inner env; to spread episodes of an expensive inner env
over processes, use ``gymnasium.make_vec(id, n, vectorization_mode="async")`` or the runner's backends (a
registered example's native vector entry point, :class:`EpisodicVectorEnv`, runs its envs serially).

Classes
-------
EpisodicEnv
    The conversion.
EpisodicVectorEnv
    Its native (serial) vector version, with per-env contexts.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from creps_gym._validation import as_float_array, check_positive_int
from creps_gym.envs.base import ContextualEpisodicEnv, ContextualEpisodicVectorEnv
from creps_gym.wrappers.access import ContextAccess, context_box, make_context_access
from creps_gym.wrappers.controllers import Controller, make_controller

__all__ = ["EpisodicEnv", "EpisodicVectorEnv"]


def _real_reward(reward: Any, step: int) -> float:
    """An inner step's reward as a float; ``TypeError`` naming it unless it is a real number.

    Python or numpy ints and floats, or 0-d real arrays, are accepted; a str, a bool, a ``Decimal`` or a
    complex number is refused, never converted.
    """
    real = isinstance(reward, (int, float, np.integer, np.floating)) and not isinstance(reward, bool)
    if isinstance(reward, np.ndarray):
        real = reward.shape == () and reward.dtype.kind in "iuf"
    if not real:
        raise TypeError(
            f"reward: expected a real number (int or float) from the inner env's step(), got "
            f"{type(reward).__name__} {reward!r} at inner step {step}"
        )
    try:
        return float(reward)
    except OverflowError:  # a Python int beyond the float range
        digits = len(str(abs(int(reward))))
        raise ValueError(
            f"reward: expected a finite real number from the inner env's step(), got an integer of {digits} "
            f"digits (beyond the float range) at inner step {step}"
        ) from None


Array = NDArray[np.float64]
SEED_RANGE = 2**31


def _make_inner(env: Any, env_kwargs: Mapping[str, Any] | None, max_inner_steps: int | None) -> gym.Env:
    if max_inner_steps is not None:  # checked here, before gymnasium.make sees it under its own name
        max_inner_steps = check_positive_int(max_inner_steps, "max_inner_steps")
    if isinstance(env, str):
        extra = {} if max_inner_steps is None else {"max_episode_steps": max_inner_steps}
        return gym.make(env, **extra, **dict(env_kwargs or {}))
    if not isinstance(env, gym.Env):
        raise TypeError(f"env: expected a gymnasium.Env or a registered id, got {type(env).__name__}")
    if env_kwargs:
        raise ValueError(f"env_kwargs: expected none when env is an instance, got {dict(env_kwargs)}")
    return env


def _horizon(inner: gym.Env, max_inner_steps: int | None) -> int:
    if max_inner_steps is not None:
        return check_positive_int(max_inner_steps, "max_inner_steps")
    limit = None if inner.spec is None else inner.spec.max_episode_steps
    if limit is None:
        raise ValueError(
            "max_inner_steps: expected a positive int because the inner env has no time limit, got None"
        )
    return int(limit)


def _check_controller(controller: Any, inner: gym.Env) -> Controller:
    if not isinstance(controller, Controller):
        raise TypeError(
            "controller: expected a Controller (action_dim, observation_dim, param_low, param_high, start, "
            f"act) or a spec mapping, got {type(controller).__name__}"
        )
    action_dim = spaces.flatdim(inner.action_space)
    if controller.action_dim != action_dim:
        raise ValueError(
            f"controller: expected action_dim {action_dim} to match the inner action space "
            f"{inner.action_space}, got a controller with action_dim {controller.action_dim}"
        )
    obs_dim = spaces.flatdim(inner.observation_space)
    if controller.observation_dim is not None and controller.observation_dim != obs_dim:
        raise ValueError(
            f"controller: expected observation_dim {obs_dim} (the flat inner observation), "
            f"got {controller.observation_dim}"
        )
    low = as_float_array(controller.param_low, "controller.param_low", (None,))
    high = as_float_array(controller.param_high, "controller.param_high", (low.shape[0],))
    if low.shape[0] == 0:
        raise ValueError("controller.param_low: expected at least one parameter, got shape (0,)")
    if not (low < high).all():
        bad = int(np.argmin(low < high))
        raise ValueError(
            f"controller.param_low, controller.param_high: expected param_low < param_high, got "
            f"{low[bad]} and {high[bad]} at index {bad}"
        )
    return controller


class EpisodicEnv(ContextualEpisodicEnv):
    """A step-based Gymnasium env run for a whole episode per action θ, as a one-step contextual env.

    Description
        The inner episode is driven by a parametric controller; the episodic env's action is the
        controller's parameter vector and its reward is the inner episode's return.
    Context Space
        ``Box(context.low, context.high)`` of the accessor (float64). Contexts drawn on reset come from the
        inner env's own task distribution.
    Parameter Space
        ``Box(controller.param_low, controller.param_high)`` (float64).
    Return
        Sum of the inner rewards over the inner episode (to be maximised).
    Episode End
        After the single step (``terminated=True``). The inner episode ends when the inner env terminates
        or truncates, or after ``max_inner_steps`` steps (then ``inner_truncated`` is True).
    Arguments
        env : str or gymnasium.Env
            Registered id (``"module:Id"`` imports ``module`` first) or an instance (then owned and closed).
        controller : Controller or mapping
            A controller, or a spec for :func:`~creps_gym.wrappers.controllers.make_controller`.
        context : ContextAccess or mapping
            An accessor, or a spec for :func:`~creps_gym.wrappers.access.make_context_access`.
        env_kwargs : mapping, optional
            Keyword arguments of ``gymnasium.make`` for an id.
        reset_options : mapping, optional
            ``options`` of every inner reset (e.g. PointMaze's fixed ``reset_cell``).
        start_seed : int
            Seed of the inner reset that starts every inner episode (default 0).
        max_inner_steps : int, optional
            Inner time limit (a ``TimeLimit`` on an inner id); default the inner spec's. It is not called
            ``max_episode_steps``, which ``gymnasium.make`` would take for the one-step env's own limit.
    Version History
        v0: initial version.
    """

    def __init__(
        self,
        env: str | gym.Env,
        controller: Controller | Mapping[str, Any],
        context: ContextAccess | Mapping[str, Any],
        *,
        env_kwargs: Mapping[str, Any] | None = None,
        reset_options: Mapping[str, Any] | None = None,
        start_seed: int = 0,
        max_inner_steps: int | None = None,
        render_mode: str | None = None,
    ) -> None:
        self.inner = _make_inner(env, env_kwargs, max_inner_steps)
        if not isinstance(self.inner.action_space, spaces.Box):
            raise TypeError(
                f"env: expected an inner env with a Box action space, got {self.inner.action_space}"
            )
        self.horizon = _horizon(self.inner, max_inner_steps)
        obs_dim = spaces.flatdim(self.inner.observation_space)
        action_dim = spaces.flatdim(self.inner.action_space)
        if isinstance(controller, Mapping):
            controller = make_controller(controller, obs_dim, action_dim, self.horizon)
        self.controller = _check_controller(controller, self.inner)
        self.access = make_context_access(context) if isinstance(context, Mapping) else context
        if not isinstance(self.access, ContextAccess):
            raise TypeError(
                f"context: expected a ContextAccess (low, high, check, read, write) or a spec mapping, "
                f"got {type(self.access).__name__}"
            )
        self.access.check(self.inner)
        self.start_seed = check_positive_int(start_seed, "start_seed", minimum=0)
        if reset_options is not None and not isinstance(reset_options, Mapping):
            raise TypeError(f"reset_options: expected a mapping or None, got {type(reset_options).__name__}")
        self.reset_options = None if reset_options is None else dict(reset_options)
        low, high = context_box(self.access)
        super().__init__(low, high, self.controller.param_low, self.controller.param_high, render_mode)

    # -- contexts from the inner env -------------------------------------------------------------------
    def sample_contexts(self, rng: np.random.Generator, n: int) -> Array:
        """Contexts (n, z) read from the inner env after resets seeded from ``rng``."""
        contexts = np.empty((n, self.context_dim))
        for i in range(n):
            seed = int(rng.integers(SEED_RANGE))
            observation, info = self.inner.reset(seed=seed, options=self.reset_options)
            contexts[i] = self.access.read(self.inner, observation, info)
        low, high = self.observation_space.low, self.observation_space.high
        if ((contexts < low) | (contexts > high)).any():
            raise RuntimeError(
                f"context: the inner env drew a context {contexts.tolist()} outside the declared box "
                f"[{low.tolist()}, {high.tolist()}]; widen the accessor's low/high"
            )
        return contexts

    # -- the inner episode -----------------------------------------------------------------------------
    def _action(self, raw: Any, step: int) -> np.ndarray:
        space = self.inner.action_space
        action = np.asarray(raw, dtype=np.float64)
        if action.shape != (self.controller.action_dim,) or not np.isfinite(action).all():
            raise RuntimeError(
                f"controller.act: expected a finite action of shape ({self.controller.action_dim},) at inner "
                f"step {step}, got {action!r}"
            )
        return np.clip(action, space.low, space.high).astype(space.dtype).reshape(space.shape)

    def rollout(self, context: Array, params: Array) -> tuple[float, int, bool, bool, dict[str, Any]]:
        """Run one inner episode.

        Parameters
        ----------
        context : ndarray, shape (z,)
        params : ndarray, shape (p,)

        Returns
        -------
        tuple
            ``(return, length, terminated, truncated, final_info)`` of the inner episode.
        """
        observation, info = self.inner.reset(seed=self.start_seed, options=self.reset_options)
        observation = self.access.write(self.inner, np.asarray(context, dtype=np.float64), observation)
        flat = spaces.flatten(self.inner.observation_space, observation).astype(np.float64)
        self.controller.start(np.asarray(params, dtype=np.float64), flat)
        total, step, terminated, truncated = 0.0, 0, False, False
        while not (terminated or truncated):
            action = self._action(self.controller.act(step, flat), step)
            observation, reward, terminated, truncated, info = self.inner.step(action)
            total += _real_reward(reward, step)
            step += 1
            truncated = bool(truncated) or (step >= self.horizon and not terminated)
            flat = spaces.flatten(self.inner.observation_space, observation).astype(np.float64)
        return total, step, bool(terminated), bool(truncated), dict(info)

    def evaluate(self, contexts: Array, params: Array) -> tuple[Array, dict[str, np.ndarray]]:
        """Run one inner episode per row of contexts (n, z) and params (n, p); returns (n,) and info."""
        n = contexts.shape[0]
        returns = np.empty(n)
        lengths = np.empty(n, dtype=np.int64)
        terminated = np.empty(n, dtype=bool)
        truncated = np.empty(n, dtype=bool)
        infos = np.empty(n, dtype=object)
        for i in range(n):
            episode = self.rollout(contexts[i], params[i])
            returns[i], lengths[i], terminated[i], truncated[i], infos[i] = episode
        info = {"inner_length": lengths, "inner_terminated": terminated, "inner_truncated": truncated}
        info["inner_info"] = infos
        return returns, info

    def close(self) -> None:
        """Close the inner env."""
        self.inner.close()
        super().close()


class EpisodicVectorEnv(ContextualEpisodicVectorEnv):
    """Native vector version of :class:`EpisodicEnv`: per-env contexts, episodes run one after another.

    ``EpisodicVectorEnv(num_envs, env=..., controller=..., context=...)``; the keyword arguments are those of
    :class:`EpisodicEnv`. For parallel episodes use ``AsyncVectorEnv`` instead.
    """

    single_env_class = EpisodicEnv

    def close_extras(self, **kwargs: Any) -> None:
        """Close the inner env."""
        self.model.close()
