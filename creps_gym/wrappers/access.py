"""How the episodic conversion reads and imposes the context of a step-based inner env.

Context accessors
-----------------
ContextAccess
    The protocol: the context box (``low``, ``high``), ``check(env)`` (raise if the inner env has no usable
    context), ``read(env, observation, info)`` and ``write(env, context, observation)``.
GoalContext
    A goal-conditioned env (Gymnasium-Robotics ``GoalEnv``: Dict observation with ``"desired_goal"`` and a
    ``goal`` attribute on the unwrapped env, e.g. PointMaze): the context is the desired goal.
QposContext
    A Gymnasium MuJoCo env whose task is set by some ``qpos`` entries (Reacher-v5's target is
    ``qpos[2:4]``): the context is those entries, imposed with ``set_state``.

Functions
---------
make_context_access
    Build an accessor from a JSON-able spec (``{"type": "goal", "low": [...], "high": [...]}``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from creps_gym._validation import as_float_array
from creps_gym.wrappers.samplers import UniformContexts

__all__ = ["ContextAccess", "GoalContext", "QposContext", "context_box", "make_context_access"]

Array = NDArray[np.float64]


@runtime_checkable
class ContextAccess(Protocol):
    """Reads and imposes the context of an inner env; ``low`` and ``high`` (z,) bound the contexts."""

    low: Array
    high: Array

    def check(self, env: gym.Env) -> None:
        """Raise ``TypeError``/``ValueError`` if ``env`` has no context this accessor can use."""

    def read(self, env: gym.Env, observation: Any, info: dict[str, Any]) -> Array:
        """The context (z,) of the episode the inner env has just been reset to."""

    def write(self, env: gym.Env, context: Array, observation: Any) -> Any:
        """Impose ``context`` (z,) on the freshly reset inner env; return the updated first observation."""


class _BoxedContext:
    """Shared context box of the accessors."""

    def __init__(self, low: Any, high: Any) -> None:
        box = UniformContexts(low, high)
        if not (np.isfinite(box.low).all() and np.isfinite(box.high).all()):
            raise ValueError(f"low/high: expected finite context bounds, got {box.low} and {box.high}")
        self.low, self.high = box.low, box.high


class GoalContext(_BoxedContext):
    """The context is a goal env's desired goal, set through the unwrapped env's ``goal`` attribute.

    After ``write`` the first observation's desired goal is replaced by the context; later observations
    and the rewards read the goal from the inner env itself. A ``update_target_site_pos()`` method (the
    maze envs' goal marker) is called when present.

    Parameters
    ----------
    low, high : array_like, shape (z,)
        The box of the goals used as contexts.
    key : str
        Key of the desired goal in the Dict observation.
    """

    def __init__(self, low: Any, high: Any, key: str = "desired_goal") -> None:
        super().__init__(low, high)
        self.key = key

    def check(self, env: gym.Env) -> None:
        """Require a Dict observation holding ``key`` (z,) and, after a reset, a ``goal`` (z,)."""
        space = env.observation_space
        if not isinstance(space, spaces.Dict) or self.key not in space.spaces:
            raise TypeError(
                f"env: GoalContext expected a goal-conditioned env with a Dict observation space holding "
                f"{self.key!r}, got {space}"
            )
        if space[self.key].shape != self.low.shape:
            raise ValueError(
                f"context low/high: expected shape {space[self.key].shape} (the inner {self.key!r}), "
                f"got {self.low.shape}"
            )
        env.reset(seed=0)  # the goal exists only after a reset
        goal = getattr(env.unwrapped, "goal", None)
        if goal is None or np.shape(goal) != self.low.shape:
            raise TypeError(
                f"env: GoalContext expected the unwrapped env to have a 'goal' array of shape "
                f"{self.low.shape} to set, got {'no goal' if goal is None else np.shape(goal)}"
            )

    def read(self, env: gym.Env, observation: Any, info: dict[str, Any]) -> Array:
        """The desired goal of the first observation, shape (z,)."""
        return np.asarray(observation[self.key], dtype=np.float64).copy()

    def write(self, env: gym.Env, context: Array, observation: Any) -> Any:
        """Set ``env.unwrapped.goal`` and the first observation's desired goal to the context."""
        inner = env.unwrapped
        inner.goal = np.array(context, dtype=np.float64)
        update_marker = getattr(inner, "update_target_site_pos", None)
        if callable(update_marker):
            update_marker()
        return {**observation, self.key: np.array(context, dtype=np.float64)}


class QposContext(_BoxedContext):
    """The context is ``qpos[indices]`` of a Gymnasium MuJoCo env, imposed with ``set_state`` after reset.

    The first observation is recomputed with the env's ``_get_obs()`` (the Gymnasium MuJoCo envs'
    convention).

    Parameters
    ----------
    indices : sequence of int, length z
        The ``qpos`` entries holding the task (Reacher-v5: ``[2, 3]``, the target's x and y).
    low, high : array_like, shape (z,)
        The box of the contexts.
    """

    def __init__(self, indices: Sequence[int], low: Any, high: Any) -> None:
        super().__init__(low, high)
        chosen = np.asarray(indices)
        if chosen.ndim != 1 or chosen.dtype.kind not in "iu" or chosen.shape != self.low.shape:
            raise ValueError(
                f"indices: expected {self.low.shape[0]} ints (one per context dimension), got {indices!r}"
            )
        self.indices = chosen.astype(np.int64)

    def check(self, env: gym.Env) -> None:
        """Require a MuJoCo env (``data.qpos``, ``set_state``, ``_get_obs``) with enough ``qpos`` entries."""
        inner = env.unwrapped
        data = getattr(inner, "data", None)
        if (
            data is None
            or not hasattr(data, "qpos")
            or not all(callable(getattr(inner, name, None)) for name in ("set_state", "_get_obs"))
        ):
            raise TypeError(
                f"env: QposContext expected a Gymnasium MuJoCo env (data.qpos, set_state, _get_obs), "
                f"got {type(inner).__name__}"
            )
        if self.indices.min() < 0 or self.indices.max() >= data.qpos.shape[0]:
            raise ValueError(
                f"indices: expected qpos indices in [0, {data.qpos.shape[0] - 1}], "
                f"got {self.indices.tolist()}"
            )

    def read(self, env: gym.Env, observation: Any, info: dict[str, Any]) -> Array:
        """``qpos[indices]`` after the reset, shape (z,)."""
        return np.array(env.unwrapped.data.qpos[self.indices], dtype=np.float64)

    def write(self, env: gym.Env, context: Array, observation: Any) -> Any:
        """Set ``qpos[indices] = context`` (velocities unchanged) and return the recomputed observation."""
        inner = env.unwrapped
        qpos, qvel = inner.data.qpos.copy(), inner.data.qvel.copy()
        qpos[self.indices] = context
        inner.set_state(qpos, qvel)
        return inner._get_obs()


def make_context_access(spec: Mapping[str, Any]) -> ContextAccess:
    """Build an accessor from ``{"type": "goal", "low", "high"[, "key"]}`` or ``{"type": "qpos", "indices",
    "low", "high"}``."""
    if not isinstance(spec, Mapping) or "type" not in spec:
        raise TypeError(f"context: expected a ContextAccess or a mapping with a 'type' key, got {spec!r}")
    options = {key: value for key, value in spec.items() if key != "type"}
    if spec["type"] == "goal":
        return GoalContext(**options)
    if spec["type"] == "qpos":
        return QposContext(**options)
    raise ValueError(f"context['type']: expected 'goal' or 'qpos', got {spec['type']!r}")


def context_box(access: Any) -> tuple[Array, Array]:
    """The validated ``(low, high)`` (z,) of a user accessor."""
    low = as_float_array(getattr(access, "low", None), "context.low", (None,))
    high = as_float_array(getattr(access, "high", None), "context.high", (low.shape[0],))
    return low, high
