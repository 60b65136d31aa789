"""Offset parametrisation: search parameters relative to a centre, in scaled units.

:class:`OffsetParams` maps the agent's ``θ_agent`` to the env's ``θ_env = centre + scale ⊙ θ_agent``. By
default the centre and the scale are the env's declared initial distribution
(:func:`creps_gym.envs.base.initial_distribution`: for the kick, its reference kick and σ), so a search
through the wrapper starts at ``θ_agent = 0`` with unit scale.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from creps_gym._validation import as_float_array
from creps_gym.envs.base import initial_distribution

__all__ = ["OffsetParams"]

Array = NDArray[np.float64]


def _per_parameter(value: Any, name: str, p: int) -> Array:
    """A scalar or a (p,) array as a finite float array of shape (p,), else a ValueError naming ``name``."""
    array = as_float_array(value, name)
    if array.shape not in ((), (p,)):
        raise ValueError(f"{name}: expected a scalar or shape ({p},), got shape {array.shape}")
    return np.broadcast_to(array, (p,)).copy()


class OffsetParams(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """Search offsets from a centre in scaled units: ``θ_env = centre + scale ⊙ θ_agent``.

    The action space is the env's box in agent units, ``(low - centre) / scale`` to
    ``(high - centre) / scale``; the map is applied as is (the env decides what it does out of its box).
    The declared initial distribution maps through the wrapper: N(mean, std²) of the env becomes
    N((mean - centre) / scale, (std / scale)²), which is N(0, 1) with the default centre and scale.

    With a contextual mean fit, the ridge of the weighted maximum-likelihood fit shrinks the coefficients
    towards zero, i.e. the policy towards the centre (not towards the middle of the env's box): the
    wrapper turns the ridge into a pull towards the centre (see ``docs/wrappers.md``).

    Parameters
    ----------
    env : gymnasium.Env
        An env with a 1-D Box action space.
    centre : array_like, shape (p,) or scalar, optional
        Default: the env's declared initial mean.
    scale : array_like, shape (p,) or scalar, optional
        Positive; default: the env's declared initial standard deviations.
    """

    def __init__(self, env: gym.Env, centre: Any = None, scale: Any = None) -> None:
        space = env.action_space
        if not isinstance(space, spaces.Box) or len(space.shape) != 1:
            raise TypeError(f"env.action_space: OffsetParams expected a 1-D Box, got {space}")
        p = space.shape[0]
        declared_mean, declared_std = initial_distribution(env)
        centre = declared_mean if centre is None else _per_parameter(centre, "centre", p)
        scale = declared_std if scale is None else _per_parameter(scale, "scale", p)
        if not (np.isfinite(centre).all() and np.isfinite(scale).all() and (scale > 0).all()):
            raise ValueError(
                f"centre, scale: expected finite values and scale > 0, got centre {centre}, scale {scale}"
            )
        with np.errstate(over="ignore"):
            in_agent_units = np.r_[(declared_mean - centre) / scale, declared_std / scale]
        if not np.isfinite(in_agent_units).all():
            raise ValueError(
                f"scale: expected values that keep the declared distribution N({declared_mean}, "
                f"{declared_std}²) finite in agent units, got {scale}"
            )
        gym.utils.RecordConstructorArgs.__init__(self, centre=centre, scale=scale)
        gym.ActionWrapper.__init__(self, env)
        self.centre, self.scale = np.array(centre, np.float64), np.array(scale, np.float64)
        self.action_space = spaces.Box(
            self.to_agent(space.low.astype(np.float64)),
            self.to_agent(space.high.astype(np.float64)),
            dtype=np.float64,
        )

    def action(self, action: Any) -> Array:
        """Map the agent's offsets (p,) to the env's parameters ``centre + scale * θ_agent`` (p,)."""
        theta = as_float_array(action, "action", (self.centre.shape[0],))
        return self.centre + self.scale * theta

    def to_env(self, offsets: Any) -> Array:
        """Batched map: agent offsets (..., p) to env parameters ``centre + scale * θ_agent`` (..., p).

        For batched evaluation through the unwrapped env's ``evaluate`` (e.g. ``benchmarks/kick/run.py``);
        with ``scale=1`` it is exactly ``centre + offsets``.
        """
        offsets = as_float_array(offsets, "offsets")
        if offsets.shape[-1:] != self.centre.shape:
            raise ValueError(f"offsets: expected shape (..., {self.centre.shape[0]}), got {offsets.shape}")
        return self.centre + self.scale * offsets

    def to_agent(self, params: Any) -> Array:
        """Inverse map: env parameters (..., p) to agent units ``(θ_env - centre) / scale`` (..., p)."""
        params = as_float_array(params, "params")
        if params.shape[-1:] != self.centre.shape:
            raise ValueError(f"params: expected shape (..., {self.centre.shape[0]}), got {params.shape}")
        return (params - self.centre) / self.scale

    def initial_distribution(self) -> tuple[Array, Array]:
        """The wrapped env's declared initial distribution in agent units (mean, std), shape (p,)."""
        mean, std = initial_distribution(self.env)
        return self.to_agent(mean), std / self.scale
