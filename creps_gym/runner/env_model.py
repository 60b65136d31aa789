"""The env a run is given, as the runner sees it: its spaces, and the creps_gym model behind its wrappers.

* :func:`check_box_spaces`: contexts and parameters are Boxes.
* :func:`unwrapped_model`: the creps_gym model behind an env, when the wrappers around it change nothing
  the evaluation computes (so the runner may evaluate the model's batched ``evaluate`` directly).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from creps_gym.envs.evaluation import contextual_model
from creps_gym.errors import ConfigTypeError
from creps_gym.wrappers import FixedContexts, SampleContexts

__all__ = ["MODEL_PRESERVING_WRAPPERS", "check_box_spaces", "unwrapped_model"]

# Wrappers that change neither the observation, the action nor the reward of a one-step episode.
MODEL_PRESERVING_WRAPPERS: tuple[type, ...] = (
    gym.wrappers.OrderEnforcing,
    gym.wrappers.PassiveEnvChecker,
    gym.wrappers.TimeLimit,
    FixedContexts,  # they choose the training contexts; the test contexts come from the model
    SampleContexts,
)


def check_box_spaces(env: gym.Env) -> None:
    """``TypeError`` unless the env's observation and action spaces are Boxes (contexts and θ)."""
    for name in ("observation_space", "action_space"):
        space = getattr(env, name)
        if not isinstance(space, gym.spaces.Box):
            raise ConfigTypeError("env", f"expected a Box {name} (contexts and parameters θ), got {space}")


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
