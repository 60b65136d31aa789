"""The initial search distribution an env declares (:func:`initial_distribution`) and the box rule every
env falls back to (:func:`box_initial_distribution`); both are re-exported by :mod:`creps_gym.envs.base`."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from creps_gym._validation import as_float_array

__all__ = ["box_initial_distribution", "initial_distribution"]

Array = NDArray[np.float64]


def box_initial_distribution(space: spaces.Box) -> tuple[Array, Array]:
    """The box rule: mean and standard deviations (p,) of a search distribution for a Box of parameters.

    The centre of the box and a quarter of its width per coordinate (so mean ± 2 std spans the box);
    coordinates with an infinite bound get mean 0 and standard deviation 1.
    """
    low, high = np.asarray(space.low, np.float64), np.asarray(space.high, np.float64)
    finite = np.isfinite(low) & np.isfinite(high)
    low, high = np.where(finite, low, -2.0), np.where(finite, high, 2.0)
    std = (high - low) / 4.0
    return np.where(finite, (low + high) / 2.0, 0.0), np.where(std > 0, std, 1.0)


def initial_distribution(env: Any) -> tuple[Array, Array]:
    """The initial search distribution N(mean, diag(std²)) that ``env`` declares: mean and std, shape (p,).

    The one hook: the ``initial_distribution()`` method of the env or of the outermost wrapper that defines
    one. Every creps_gym env has it (:class:`ContextualEpisodicEnv`); parameter wrappers map it
    (:class:`~creps_gym.wrappers.NormalizeParams`, :class:`~creps_gym.wrappers.OffsetParams`). Envs without
    it, and declarations made in other parameter units (the declaring layer's action space differs from
    ``env.action_space``: a wrapper between changed the parameters without mapping the distribution),
    fall back to :func:`box_initial_distribution`.
    """
    layer = env
    while not hasattr(type(layer), "initial_distribution") and isinstance(layer, gym.Wrapper):
        layer = layer.env
    if hasattr(type(layer), "initial_distribution") and layer.action_space == env.action_space:
        return _checked_declaration(layer, env.action_space.shape)
    return box_initial_distribution(env.action_space)


def _checked_declaration(layer: Any, shape: tuple[int, ...]) -> tuple[Array, Array]:
    """``layer.initial_distribution()`` checked: finite real mean and std of ``shape``, std > 0."""
    name = f"{type(layer).__name__}.initial_distribution()"
    declared = layer.initial_distribution()
    if not isinstance(declared, tuple) or len(declared) != 2:
        raise TypeError(f"{name}: expected a tuple (mean, std), got {type(declared).__name__}")
    mean = as_float_array(declared[0], f"{name} mean", shape).copy()
    std = as_float_array(declared[1], f"{name} std", shape).copy()
    if not (std > 0).all():
        raise ValueError(f"{name} std: expected values > 0, got {std}")
    return mean, std
